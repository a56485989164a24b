/* navdeck_fw_host: the portable firmware core as an emulated base on a pseudo-terminal.
 *
 *   navdeck_fw_host --link /tmp/dev/base [--kinematics skid|diff|omni] [--wheels N]
 *                   [--wheel-radius M] [--track-width M] [--wheel-base M] [--omni-radius M]
 *                   [--ticks-per-rev N] [--battery-cutoff V] [--battery V] [--flash FILE]
 *                   [--max-wheel-speed RAD_S] [--ir-bits N]
 *
 * Prints "ready LINK" once the link exists. Signals stand in for the cable and the board:
 * SIGUSR1 unplugs (the link vanishes, the core keeps running: its watchdog stops the motors),
 * SIGUSR2 plugs it back in (a new pty, the same link), SIGHUP fails the IMU (toggle),
 * SIGTERM / SIGINT exit. */
#define _DEFAULT_SOURCE
#define _XOPEN_SOURCE 700
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "hal_host.h"
#include "nd_core.h"

static volatile sig_atomic_t g_unplug, g_replug, g_quit, g_imu_toggle;

static void on_signal(int sig) {
    if (sig == SIGUSR1) g_unplug = 1;
    else if (sig == SIGUSR2) g_replug = 1;
    else if (sig == SIGHUP) g_imu_toggle = 1;
    else g_quit = 1;
}

static void usage(void) {
    fprintf(stderr, "usage: navdeck_fw_host --link PATH [--kinematics skid|diff|omni] [--wheels N] "
                    "[--wheel-radius M] [--track-width M] [--wheel-base M] [--omni-radius M] "
                    "[--ticks-per-rev N] [--battery-cutoff V] [--battery V] [--flash FILE] "
                    "[--max-wheel-speed RAD_S] [--ir-bits N]\n");
    exit(2);
}

static double number(const char *opt, const char *s) {
    char *end;
    double v = strtod(s, &end);
    if (*s == 0 || *end != 0) {
        fprintf(stderr, "navdeck_fw_host: %s needs a number, got %s\n", opt, s);
        exit(2);
    }
    return v;
}

int main(int argc, char **argv) {
    nd_board_t board = {ND_KIN_SKID, 4, 20.0f};
    nd_geometry_t geo = {0.0325f, 0.19f, 0.15f, 1320.0f, 0.25f, 10.5f};
    double battery = 12.0;
    int wheels = 0;
    for (int i = 1; i < argc; i++) {
        const char *a = argv[i];
        if (i + 1 >= argc) usage();
        const char *v = argv[++i];
        if (!strcmp(a, "--link")) g_host.link = v;
        else if (!strcmp(a, "--flash")) g_host.flash_path = v;
        else if (!strcmp(a, "--kinematics")) {
            if (!strcmp(v, "skid")) board.kinematics = ND_KIN_SKID;
            else if (!strcmp(v, "diff")) board.kinematics = ND_KIN_DIFF;
            else if (!strcmp(v, "omni")) board.kinematics = ND_KIN_OMNI;
            else usage();
        } else if (!strcmp(a, "--wheels")) wheels = (int)number(a, v);
        else if (!strcmp(a, "--wheel-radius")) geo.wheel_radius = (float)number(a, v);
        else if (!strcmp(a, "--track-width")) geo.track_width = (float)number(a, v);
        else if (!strcmp(a, "--wheel-base")) geo.wheel_base = (float)number(a, v);
        else if (!strcmp(a, "--omni-radius")) geo.omni_radius = (float)number(a, v);
        else if (!strcmp(a, "--ticks-per-rev")) geo.ticks_per_rev = (float)number(a, v);
        else if (!strcmp(a, "--battery-cutoff")) geo.battery_cutoff = (float)number(a, v);
        else if (!strcmp(a, "--battery")) battery = number(a, v);
        else if (!strcmp(a, "--max-wheel-speed")) board.wheel_max_rad_s = (float)number(a, v);
        else if (!strcmp(a, "--ir-bits")) g_host.ir_bits = (uint8_t)number(a, v); /* sensors seeing an obstacle */
        else usage();
    }
    if (!g_host.link) usage();
    board.wheels = wheels ? (unsigned)wheels : (board.kinematics == ND_KIN_DIFF ? 2u : 4u);
    if (board.wheels != 2 && board.wheels != 4) usage();
    if (board.kinematics == ND_KIN_OMNI && board.wheels != 4) usage();

    /* the plant moves with the true geometry; the firmware uses its parameters (defaults equal) */
    nd_plant_t *p = &g_host.plant;
    memset(p, 0, sizeof *p);
    p->kinematics = board.kinematics;
    p->wheels = board.wheels;
    p->wheel_radius = geo.wheel_radius;
    p->track_width = geo.track_width;
    p->omni_radius = geo.omni_radius;
    p->ticks_per_rev = geo.ticks_per_rev;
    p->motor_max_rad_s = 0.9 * (double)board.wheel_max_rad_s; /* loaded motors: the PID makes up the rest */
    p->tau_s = 0.05;
    p->battery_v = battery;

    struct sigaction sa;
    memset(&sa, 0, sizeof sa);
    sa.sa_handler = on_signal;
    sigaction(SIGUSR1, &sa, NULL);
    sigaction(SIGUSR2, &sa, NULL);
    sigaction(SIGHUP, &sa, NULL);
    sigaction(SIGTERM, &sa, NULL);
    sigaction(SIGINT, &sa, NULL);

    if (host_plug() != 0) {
        perror("navdeck_fw_host: cannot create the pseudo-terminal link");
        return 1;
    }
    g_host.boot_s = host_now_s();
    static nd_core_t core;
    nd_core_init(&core, &board, &geo);
    printf("ready %s\n", g_host.link);
    fflush(stdout);

    double last = host_now_s();
    while (!g_quit) {
        host_wait_input(0.001);
        if (g_unplug) {
            g_unplug = 0;
            host_unplug();
        }
        if (g_replug) {
            g_replug = 0;
            if (host_plug() != 0) perror("navdeck_fw_host: replug failed");
        }
        if (g_imu_toggle) {
            g_imu_toggle = 0;
            g_host.imu_error = g_host.imu_error ? 0 : 5; /* I2C error 5: no ACK */
        }
        const double now = host_now_s();
        nd_plant_step(p, now - last);
        last = now;
        nd_core_step(&core);
        if (g_host.reboot) { /* RESET mode 2: a fresh core (parameters from flash), the pty stays */
            g_host.reboot = false;
            g_host.boot_s = host_now_s();
            nd_core_init(&core, &board, &geo);
        }
    }
    host_unplug();
    return 0;
}
