/* Host test program for navdeck_protocol.h. One request per stdin line, one answer line each:
 *   crc HEX                  -> CRC-16 as 4 hex digits
 *   cobs HEX / uncobs HEX    -> encoded / decoded hex ("ERR" if malformed)
 *   frame TYPE SEQ HEX       -> the wire frame (delimiter included) of a raw body
 *   pack NAME SEQ V...       -> the wire frame of a message built from its packed struct's fields
 *   stream HEX               -> each good frame as "TYPE:SEQ:BODYHEX", then "good=N drops=a,b,..."
 *   unpack HEX               -> a frame's fields decoded through the packed structs ("DROP n" if bad)
 * tests/test_firmware_protocol.py drives it and compares every answer with robot/serial. */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "navdeck_protocol.h"

#define MAXBYTES 4096

static size_t unhex(const char *s, uint8_t *out) {
    size_t n = 0;
    while (s[0] && s[1] && s[0] != '\n' && n < MAXBYTES) {
        unsigned v;
        if (sscanf(s, "%2x", &v) != 1) break;
        out[n++] = (uint8_t)v;
        s += 2;
    }
    return n;
}

static void puthex(const uint8_t *p, size_t n) {
    for (size_t i = 0; i < n; i++) printf("%02x", p[i]);
}

static void print_frame(void *ctx, const nd_frame_t *f) {
    (void)ctx;
    printf("%02x:%02x:", f->type, f->seq);
    puthex(f->body, f->body_len);
    printf(" ");
}

/* Fill the packed struct of message NAME from the numbers in `args` (field order of the spec). */
static int pack(const char *name, char *args, uint8_t *type, uint8_t *body, size_t *len) {
    double v[16] = {0};
    int k = 0;
    for (char *tok = strtok(args, " \n"); tok && k < 16; tok = strtok(NULL, " \n")) v[k++] = strtod(tok, NULL);
    if (!strcmp(name, "velocity")) {
        nd_velocity_t m = {(float)v[0], (float)v[1], (float)v[2]};
        *type = ND_MSG_VELOCITY; memcpy(body, &m, *len = sizeof m);
    } else if (!strcmp(name, "heartbeat")) {
        nd_heartbeat_t m = {(uint32_t)v[0]};
        *type = ND_MSG_HEARTBEAT; memcpy(body, &m, *len = sizeof m);
    } else if (!strcmp(name, "estop")) {
        *type = ND_MSG_ESTOP; *len = 0;
    } else if (!strcmp(name, "param_save")) {
        *type = ND_MSG_PARAM_SAVE; *len = 0;
    } else if (!strcmp(name, "reset")) {
        nd_reset_t m = {(uint8_t)v[0]};
        *type = ND_MSG_RESET; memcpy(body, &m, *len = sizeof m);
    } else if (!strcmp(name, "telemetry")) {
        nd_telemetry_t m;
        m.mcu_us = (uint32_t)v[0];
        for (int i = 0; i < 4; i++) m.enc[i] = (int32_t)v[1 + i];
        m.gyro_z = (float)v[5]; m.accel_x = (float)v[6]; m.accel_y = (float)v[7]; m.accel_z = (float)v[8];
        m.ir_bits = (uint8_t)v[9]; m.battery_mv = (uint16_t)v[10]; m.status = (uint16_t)v[11];
        *type = ND_MSG_TELEMETRY; memcpy(body, &m, *len = sizeof m);
    } else if (!strcmp(name, "param_get")) {
        nd_param_get_t m = {(uint8_t)v[0]};
        *type = ND_MSG_PARAM_GET; memcpy(body, &m, *len = sizeof m);
    } else if (!strcmp(name, "param_set")) {
        nd_param_set_t m = {(uint8_t)v[0], (float)v[1]};
        *type = ND_MSG_PARAM_SET; memcpy(body, &m, *len = sizeof m);
    } else if (!strcmp(name, "param_value")) {
        nd_param_value_t m = {(uint8_t)v[0], (float)v[1], (uint8_t)v[2]};
        *type = ND_MSG_PARAM_VALUE; memcpy(body, &m, *len = sizeof m);
    } else if (!strcmp(name, "error")) {
        nd_error_t m = {(uint8_t)v[0], (uint8_t)v[1], (uint32_t)v[2]};
        *type = ND_MSG_ERROR; memcpy(body, &m, *len = sizeof m);
    } else {
        return -1;
    }
    return 0;
}

static void unpack(const nd_frame_t *f) {
    printf("%02x %u", f->type, f->seq);
    switch (f->type) {
    case ND_MSG_VELOCITY: { nd_velocity_t m; memcpy(&m, f->body, sizeof m);
        printf(" %.9g %.9g %.9g", (double)m.vx, (double)m.vy, (double)m.wz); break; }
    case ND_MSG_HEARTBEAT: { nd_heartbeat_t m; memcpy(&m, f->body, sizeof m); printf(" %u", m.host_ms); break; }
    case ND_MSG_RESET: { nd_reset_t m; memcpy(&m, f->body, sizeof m); printf(" %u", m.mode); break; }
    case ND_MSG_TELEMETRY: { nd_telemetry_t m; memcpy(&m, f->body, sizeof m);
        printf(" %u %d %d %d %d %.9g %.9g %.9g %.9g %u %u %u", m.mcu_us, m.enc[0], m.enc[1], m.enc[2], m.enc[3],
               (double)m.gyro_z, (double)m.accel_x, (double)m.accel_y, (double)m.accel_z, m.ir_bits, m.battery_mv, m.status); break; }
    case ND_MSG_PARAM_GET: { nd_param_get_t m; memcpy(&m, f->body, sizeof m); printf(" %u", m.id); break; }
    case ND_MSG_PARAM_SET: { nd_param_set_t m; memcpy(&m, f->body, sizeof m); printf(" %u %.9g", m.id, (double)m.value); break; }
    case ND_MSG_PARAM_VALUE: { nd_param_value_t m; memcpy(&m, f->body, sizeof m);
        printf(" %u %.9g %u", m.id, (double)m.value, m.status); break; }
    case ND_MSG_ERROR: { nd_error_t m; memcpy(&m, f->body, sizeof m);
        printf(" %u %u %u", m.code, m.severity, m.detail); break; }
    default: break;
    }
}

int main(void) {
    static char line[4 * MAXBYTES];
    static uint8_t in[MAXBYTES], out[2 * MAXBYTES];
    if (nd_crc16((const uint8_t *)"123456789", 9) != 0x29B1) {
        fprintf(stderr, "CRC check value wrong\n");
        return 2;
    }
    while (fgets(line, sizeof line, stdin)) {
        char op[16] = {0};
        int skip = 0;
        if (sscanf(line, "%15s %n", op, &skip) != 1) continue;
        char *arg = line + skip;
        if (!strcmp(op, "crc")) {
            size_t n = unhex(arg, in);
            printf("%04x", nd_crc16(in, n));
        } else if (!strcmp(op, "cobs")) {
            size_t n = unhex(arg, in);
            puthex(out, nd_cobs_encode(in, n, out));
        } else if (!strcmp(op, "uncobs")) {
            size_t n = unhex(arg, in);
            int m = nd_cobs_decode(in, n, out, sizeof out);
            if (m < 0) printf("ERR"); else puthex(out, (size_t)m);
        } else if (!strcmp(op, "frame")) {
            unsigned type, seq;
            int used = 0;
            if (sscanf(arg, "%x %u %n", &type, &seq, &used) < 2) { printf("ERR"); goto next; }
            size_t n = unhex(arg + used, in);
            size_t m = nd_frame_encode((uint8_t)type, (uint8_t)seq, in, n, out);
            if (m == 0) printf("ERR"); else puthex(out, m);
        } else if (!strcmp(op, "pack")) {
            char name[32];
            unsigned seq;
            int used = 0;
            uint8_t type;
            size_t len = 0;
            if (sscanf(arg, "%31s %u %n", name, &seq, &used) < 2 || pack(name, arg + used, &type, in, &len)) {
                printf("ERR");
                goto next;
            }
            puthex(out, nd_frame_encode(type, (uint8_t)seq, in, len, out));
        } else if (!strcmp(op, "stream")) {
            static nd_rx_t rx;
            nd_rx_init(&rx);
            size_t n = unhex(arg, in);
            nd_rx_feed(&rx, in, n, print_frame, NULL);
            printf("good=%u drops=", rx.good);
            for (int i = 1; i < ND_DROP_COUNT; i++) printf(i > 1 ? ",%u" : "%u", rx.drops[i]);
        } else if (!strcmp(op, "unpack")) {
            nd_frame_t f;
            size_t n = unhex(arg, in);
            if (n && in[n - 1] == 0) n--;
            enum nd_drop why = nd_frame_decode(in, n, &f);
            if (why != ND_FRAME_OK) printf("DROP %d", (int)why); else unpack(&f);
        } else {
            printf("ERR");
        }
    next:
        printf("\n");
        fflush(stdout);
    }
    return 0;
}
