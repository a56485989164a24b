#define _DEFAULT_SOURCE
#define _XOPEN_SOURCE 700
#include "hal_host.h"

#include <errno.h>
#include <fcntl.h>
#include <poll.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <termios.h>
#include <time.h>
#include <unistd.h>

#include "hal.h"

hal_host_t g_host = {.master = -1, .slave = -1};

double host_now_s(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + (double)ts.tv_nsec * 1e-9;
}

int host_plug(void) {
    if (g_host.master >= 0) return 0;
    int m = posix_openpt(O_RDWR | O_NOCTTY);
    if (m < 0 || grantpt(m) != 0 || unlockpt(m) != 0) return -1;
    const char *name = ptsname(m);
    if (!name) return -1;
    /* keep our own slave descriptor open: the master never sees EIO while no client is attached
     * (a UART with the cable in but nobody listening) */
    int s = open(name, O_RDWR | O_NOCTTY);
    if (s < 0) return -1;
    struct termios t;
    if (tcgetattr(s, &t) == 0) {
        cfmakeraw(&t); /* no echo, no line discipline: bytes pass unchanged */
        tcsetattr(s, TCSANOW, &t);
    }
    fcntl(m, F_SETFL, fcntl(m, F_GETFL) | O_NONBLOCK);
    char tmp[4096];
    snprintf(tmp, sizeof tmp, "%s.tmp", g_host.link);
    unlink(tmp);
    if (symlink(name, tmp) != 0 || rename(tmp, g_host.link) != 0) return -1;
    g_host.master = m;
    g_host.slave = s;
    return 0;
}

void host_unplug(void) {
    unlink(g_host.link);
    if (g_host.master >= 0) close(g_host.master);
    if (g_host.slave >= 0) close(g_host.slave);
    g_host.master = g_host.slave = -1;
}

void host_wait_input(double timeout_s) {
    if (g_host.master < 0) {
        struct timespec ts = {0, (long)(timeout_s * 1e9)};
        nanosleep(&ts, NULL);
        return;
    }
    struct pollfd p = {g_host.master, POLLIN, 0};
    poll(&p, 1, (int)(timeout_s * 1000.0 + 0.5));
}

/* ---- hal.h ------------------------------------------------------------------------------------ */
uint32_t hal_micros(void) { return (uint32_t)(uint64_t)((host_now_s() - g_host.boot_s) * 1e6); }

size_t hal_uart_read(uint8_t *buf, size_t cap) {
    if (g_host.master < 0) return 0;
    ssize_t n = read(g_host.master, buf, cap);
    return n > 0 ? (size_t)n : 0;
}

void hal_uart_write(const uint8_t *buf, size_t n) {
    if (g_host.master < 0) return; /* unplugged: the bytes go nowhere */
    ssize_t w = write(g_host.master, buf, n);
    (void)w; /* a full pty buffer drops the rest, as a UART nobody reads */
}

uint16_t hal_encoder_raw(unsigned wheel) { return nd_plant_encoder(&g_host.plant, wheel); }

void hal_motor_set(unsigned wheel, float duty) {
    g_host.plant.brake = false;
    g_host.plant.duty[wheel] = duty;
}

void hal_motor_brake_all(void) {
    memset(g_host.plant.duty, 0, sizeof g_host.plant.duty);
    g_host.plant.brake = true;
}

int hal_imu_read(float *gyro_z, float accel[3]) {
    if (g_host.imu_error) return g_host.imu_error;
    *gyro_z = (float)g_host.plant.yaw_rate;
    accel[0] = 0.0f;
    accel[1] = 0.0f;
    accel[2] = 9.81f;
    return 0;
}

uint8_t hal_ir_bits(void) { return g_host.ir_bits; }

uint16_t hal_battery_mv(void) { return (uint16_t)(g_host.plant.battery_v * 1000.0); }

int hal_flash_read(void *buf, size_t n) {
    if (!g_host.flash_path) return -1;
    FILE *f = fopen(g_host.flash_path, "rb");
    if (!f) return -1;
    size_t got = fread(buf, 1, n, f);
    fclose(f);
    return got == n ? 0 : -1;
}

int hal_flash_write(const void *buf, size_t n) {
    if (!g_host.flash_path) return -1;
    char tmp[4096];
    snprintf(tmp, sizeof tmp, "%s.tmp", g_host.flash_path);
    FILE *f = fopen(tmp, "wb");
    if (!f) return -1;
    size_t put = fwrite(buf, 1, n, f);
    if (fclose(f) != 0 || put != n) return -1;
    return rename(tmp, g_host.flash_path) == 0 ? 0 : -1; /* atomic, like an erase + program + verify */
}

void hal_reboot(void) { g_host.reboot = true; }
