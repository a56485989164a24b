/* navdeck base protocol, version 1 (docs/serial-protocol.md): frames as packed structs, message
 * ids, CRC-16/CCITT-FALSE and COBS encode/decode. Portable C11, no malloc, no libc beyond
 * <stdint.h>/<stddef.h>/<string.h>; every function is static inline so a firmware includes only
 * this file. Little-endian targets only (Cortex-M, x86, aarch64): the packed structs ARE the wire
 * layout, so no byte swapping is done. The Python side (robot/serial/framing.py, protocol.py) is
 * the reference; tests/test_firmware_protocol.py checks this file against it byte for byte. */
#ifndef NAVDECK_PROTOCOL_H
#define NAVDECK_PROTOCOL_H

#include <stddef.h>
#include <stdint.h>
#include <string.h>

#if defined(__BYTE_ORDER__) && __BYTE_ORDER__ != __ORDER_LITTLE_ENDIAN__
#error "navdeck_protocol.h: the packed structs are the little-endian wire layout"
#endif

#define ND_PROTOCOL_VERSION 1u
#define ND_HEADER_SIZE 3u      /* version, type, seq */
#define ND_CRC_SIZE 2u
#define ND_MIN_PAYLOAD (ND_HEADER_SIZE + ND_CRC_SIZE)
#define ND_MAX_PAYLOAD 254u    /* header + body + crc */
#define ND_MAX_ENCODED 256u    /* COBS(payload) without the 0x00 delimiter */
#define ND_MAX_BODY (ND_MAX_PAYLOAD - ND_MIN_PAYLOAD)

/* ---- message ids ------------------------------------------------------------------------------ */
enum nd_msg_type {
    ND_MSG_VELOCITY = 0x01,    /* host -> base */
    ND_MSG_HEARTBEAT = 0x02,   /* host -> base */
    ND_MSG_ESTOP = 0x03,       /* host -> base */
    ND_MSG_RESET = 0x04,       /* host -> base */
    ND_MSG_TELEMETRY = 0x10,   /* base -> host */
    ND_MSG_PARAM_GET = 0x20,   /* host -> base */
    ND_MSG_PARAM_SET = 0x21,   /* host -> base */
    ND_MSG_PARAM_VALUE = 0x22, /* base -> host */
    ND_MSG_PARAM_SAVE = 0x23,  /* host -> base: write the parameters to flash */
    ND_MSG_ERROR = 0x30,       /* base -> host */
};

enum nd_status_bits {
    ND_STATUS_ESTOP_LATCHED = 1u << 0,
    ND_STATUS_OBSTACLE_STOP = 1u << 1,
    ND_STATUS_WATCHDOG_STOP = 1u << 2,
    ND_STATUS_MOTOR_FAULT = 1u << 3,
    ND_STATUS_IMU_FAULT = 1u << 4,
    ND_STATUS_LOW_BATTERY = 1u << 5,
    ND_STATUS_PARAMS_DEFAULT = 1u << 6,
};

enum nd_reset_mode { ND_RESET_CLEAR_ESTOP = 0, ND_RESET_ZERO_ENCODERS = 1, ND_RESET_REBOOT = 2 };

enum nd_param_id {
    ND_PARAM_SAVE_ALL = 0, /* PARAM_VALUE id of the answer to PARAM_SAVE */
    ND_PARAM_WHEEL_RADIUS = 1,
    ND_PARAM_TRACK_WIDTH = 2,
    ND_PARAM_WHEEL_BASE = 3,
    ND_PARAM_TICKS_PER_REV = 4,
    ND_PARAM_PID_KP = 5,
    ND_PARAM_PID_KI = 6,
    ND_PARAM_PID_KD = 7,
    ND_PARAM_CMD_TIMEOUT = 8,
    ND_PARAM_TELEMETRY_RATE = 9,
    ND_PARAM_OBSTACLE_STOP_ENABLE = 10,
    ND_PARAM_OMNI_RADIUS = 11,
    ND_PARAM_BATTERY_CUTOFF = 12,
    ND_PARAM_COUNT = 13 /* ids 1..12 are valid */
};

enum nd_param_status {
    ND_PARAM_OK = 0,
    ND_PARAM_UNKNOWN_ID = 1,
    ND_PARAM_OUT_OF_RANGE = 2,
    ND_PARAM_READ_ONLY = 3,
    ND_PARAM_FLASH_ERROR = 4,
};

enum nd_error_code {
    ND_ERR_BAD_FRAME = 1,
    ND_ERR_UNKNOWN_MESSAGE = 2,
    ND_ERR_MOTOR_FAULT = 3,
    ND_ERR_IMU_FAULT = 4,
    ND_ERR_WATCHDOG = 5,
    ND_ERR_BROWN_OUT = 6,
    ND_ERR_PARAM = 7,
};

enum nd_severity { ND_SEV_INFO = 0, ND_SEV_WARNING = 1, ND_SEV_ERROR = 2 };

/* ---- bodies (packed, little-endian) ----------------------------------------------------------- */
#define ND_PACKED __attribute__((packed))

typedef struct ND_PACKED { float vx, vy, wz; } nd_velocity_t;
typedef struct ND_PACKED { uint32_t host_ms; } nd_heartbeat_t;
typedef struct ND_PACKED { uint8_t mode; } nd_reset_t;
typedef struct ND_PACKED {
    uint32_t mcu_us;
    int32_t enc[4];
    float gyro_z;
    float accel_x, accel_y, accel_z;
    uint8_t ir_bits;
    uint16_t battery_mv;
    uint16_t status;
} nd_telemetry_t;
typedef struct ND_PACKED { uint8_t id; } nd_param_get_t;
typedef struct ND_PACKED { uint8_t id; float value; } nd_param_set_t;
typedef struct ND_PACKED { uint8_t id; float value; uint8_t status; } nd_param_value_t;
typedef struct ND_PACKED { uint8_t code; uint8_t severity; uint32_t detail; } nd_error_t;
/* ESTOP and PARAM_SAVE have empty bodies. */
typedef struct ND_PACKED { uint8_t version, type, seq; } nd_header_t;

_Static_assert(sizeof(float) == 4, "float must be IEEE-754 binary32");
_Static_assert(sizeof(nd_header_t) == 3, "header");
_Static_assert(sizeof(nd_velocity_t) == 12, "VELOCITY body");
_Static_assert(sizeof(nd_heartbeat_t) == 4, "HEARTBEAT body");
_Static_assert(sizeof(nd_reset_t) == 1, "RESET body");
_Static_assert(sizeof(nd_telemetry_t) == 41, "TELEMETRY body");
_Static_assert(sizeof(nd_param_get_t) == 1, "PARAM_GET body");
_Static_assert(sizeof(nd_param_set_t) == 5, "PARAM_SET body");
_Static_assert(sizeof(nd_param_value_t) == 6, "PARAM_VALUE body");
_Static_assert(sizeof(nd_error_t) == 6, "ERROR body");

/* Body size of a message type, or -1 for an unknown type (the receiver's unknown_type check). */
static inline int nd_body_size(uint8_t type) {
    switch (type) {
    case ND_MSG_VELOCITY: return (int)sizeof(nd_velocity_t);
    case ND_MSG_HEARTBEAT: return (int)sizeof(nd_heartbeat_t);
    case ND_MSG_ESTOP: return 0;
    case ND_MSG_RESET: return (int)sizeof(nd_reset_t);
    case ND_MSG_TELEMETRY: return (int)sizeof(nd_telemetry_t);
    case ND_MSG_PARAM_GET: return (int)sizeof(nd_param_get_t);
    case ND_MSG_PARAM_SET: return (int)sizeof(nd_param_set_t);
    case ND_MSG_PARAM_VALUE: return (int)sizeof(nd_param_value_t);
    case ND_MSG_PARAM_SAVE: return 0;
    case ND_MSG_ERROR: return (int)sizeof(nd_error_t);
    default: return -1;
    }
}

/* ---- CRC-16/CCITT-FALSE: poly 0x1021, init 0xFFFF, no reflection, no final xor ----------------- */
static inline uint16_t nd_crc16_update(uint16_t crc, const uint8_t *p, size_t n) {
    while (n--) {
        crc ^= (uint16_t)((uint16_t)(*p++) << 8);
        for (int i = 0; i < 8; i++) crc = (crc & 0x8000u) ? (uint16_t)((crc << 1) ^ 0x1021u) : (uint16_t)(crc << 1);
    }
    return crc;
}
static inline uint16_t nd_crc16(const uint8_t *p, size_t n) { return nd_crc16_update(0xFFFFu, p, n); }

/* ---- COBS ---------------------------------------------------------------------------------------
 * Canonical encoder (same bytes as framing.cobs_encode: no trailing 0x01 after a final full
 * 254-byte block). `out` needs n + n/254 + 1 bytes. Returns the encoded length (no delimiter). */
static inline size_t nd_cobs_encode(const uint8_t *in, size_t n, uint8_t *out) {
    size_t code_at = 0, o = 1;
    uint8_t code = 1;
    for (size_t i = 0; i < n; i++) {
        if (in[i] == 0) {
            out[code_at] = code;
            code_at = o++;
            code = 1;
            continue;
        }
        out[o++] = in[i];
        if (++code == 0xFF) {
            out[code_at] = code;
            if (i + 1 == n) return o; /* canonical: a final full block needs no empty block */
            code_at = o++;
            code = 1;
        }
    }
    out[code_at] = code;
    return o;
}

/* Decode one COBS frame (delimiter excluded) into `out` (capacity `cap`). Returns the decoded
 * length, or -1 if malformed (empty, a 0x00 inside, a code byte past the end, or too long). */
static inline int nd_cobs_decode(const uint8_t *in, size_t n, uint8_t *out, size_t cap) {
    size_t i = 0, o = 0;
    if (n == 0) return -1;
    while (i < n) {
        uint8_t code = in[i];
        if (code == 0) return -1;
        size_t end = i + code;
        if (end > n) return -1;
        for (size_t k = i + 1; k < end; k++) {
            if (in[k] == 0 || o >= cap) return -1;
            out[o++] = in[k];
        }
        i = end;
        if (code != 0xFF && i < n) {
            if (o >= cap) return -1;
            out[o++] = 0;
        }
    }
    return (int)o;
}

/* ---- whole frames ------------------------------------------------------------------------------
 * nd_frame_encode: `out` (>= ND_MAX_ENCODED + 1 bytes) receives COBS(version type seq body crc) and
 * the 0x00 delimiter. Returns the number of bytes to send, or 0 if the body is too long. */
static inline size_t nd_frame_encode(uint8_t type, uint8_t seq, const void *body, size_t body_len, uint8_t *out) {
    uint8_t payload[ND_MAX_PAYLOAD];
    if (body_len > ND_MAX_BODY) return 0;
    payload[0] = ND_PROTOCOL_VERSION;
    payload[1] = type;
    payload[2] = seq;
    if (body_len) memcpy(payload + ND_HEADER_SIZE, body, body_len);
    size_t n = ND_HEADER_SIZE + body_len;
    uint16_t crc = nd_crc16(payload, n);
    payload[n++] = (uint8_t)(crc & 0xFFu);
    payload[n++] = (uint8_t)(crc >> 8);
    size_t e = nd_cobs_encode(payload, n, out);
    out[e++] = 0;
    return e;
}

/* Why a received frame was dropped (the order of the checks in docs/serial-protocol.md). */
enum nd_drop {
    ND_FRAME_OK = 0,
    ND_DROP_OVERSIZE,
    ND_DROP_BAD_COBS,
    ND_DROP_BAD_LENGTH,
    ND_DROP_BAD_CRC,
    ND_DROP_BAD_VERSION,
    ND_DROP_UNKNOWN_TYPE,
    ND_DROP_COUNT
};

typedef struct {
    uint8_t type, seq;
    uint8_t body_len;
    uint8_t body[ND_MAX_BODY];
} nd_frame_t;

/* Check and unpack one encoded frame (delimiter excluded). */
static inline enum nd_drop nd_frame_decode(const uint8_t *enc, size_t n, nd_frame_t *f) {
    uint8_t payload[ND_MAX_PAYLOAD];
    if (n > ND_MAX_ENCODED) return ND_DROP_OVERSIZE;
    int len = nd_cobs_decode(enc, n, payload, sizeof payload);
    if (len < 0) return ND_DROP_BAD_COBS;
    if ((size_t)len < ND_MIN_PAYLOAD) return ND_DROP_BAD_LENGTH;
    uint16_t crc = (uint16_t)(payload[len - 2] | (payload[len - 1] << 8));
    if (nd_crc16(payload, (size_t)len - ND_CRC_SIZE) != crc) return ND_DROP_BAD_CRC;
    if (payload[0] != ND_PROTOCOL_VERSION) return ND_DROP_BAD_VERSION;
    int want = nd_body_size(payload[1]);
    if (want < 0) return ND_DROP_UNKNOWN_TYPE;
    size_t body_len = (size_t)len - ND_MIN_PAYLOAD;
    if (body_len != (size_t)want) return ND_DROP_BAD_LENGTH;
    f->type = payload[1];
    f->seq = payload[2];
    f->body_len = (uint8_t)body_len;
    memcpy(f->body, payload + ND_HEADER_SIZE, body_len);
    return ND_FRAME_OK;
}

/* Streaming receiver: feed bytes as they come (UART DMA ring, read()); `on_frame` is called for
 * every good frame. Never stops on an error: the next 0x00 starts a fresh frame. */
typedef struct {
    uint8_t buf[ND_MAX_ENCODED];
    size_t len;
    uint8_t discarding; /* inside an oversize run: skip until the next 0x00 */
    uint32_t good;
    uint32_t drops[ND_DROP_COUNT];
} nd_rx_t;

typedef void (*nd_frame_cb)(void *ctx, const nd_frame_t *frame);

static inline void nd_rx_init(nd_rx_t *rx) { memset(rx, 0, sizeof *rx); }

static inline void nd_rx_feed(nd_rx_t *rx, const uint8_t *data, size_t n, nd_frame_cb cb, void *ctx) {
    for (size_t i = 0; i < n; i++) {
        uint8_t b = data[i];
        if (b != 0) {
            if (rx->discarding) continue;
            if (rx->len >= ND_MAX_ENCODED) {
                rx->drops[ND_DROP_OVERSIZE]++;
                rx->discarding = 1;
                rx->len = 0;
                continue;
            }
            rx->buf[rx->len++] = b;
            continue;
        }
        if (rx->discarding) {
            rx->discarding = 0;
        } else if (rx->len) { /* an empty frame (two delimiters) is ignored silently */
            nd_frame_t f;
            enum nd_drop why = nd_frame_decode(rx->buf, rx->len, &f);
            if (why == ND_FRAME_OK) {
                rx->good++;
                cb(ctx, &f);
            } else {
                rx->drops[why]++;
            }
        }
        rx->len = 0;
    }
}

static inline uint32_t nd_rx_bad(const nd_rx_t *rx) {
    uint32_t s = 0;
    for (int i = 1; i < ND_DROP_COUNT; i++) s += rx->drops[i];
    return s;
}

#endif /* NAVDECK_PROTOCOL_H */
