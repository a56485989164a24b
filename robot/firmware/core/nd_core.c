#include "nd_core.h"

#include <math.h>
#include <string.h>

#include "hal.h"

/* Wrap-safe "now is at or after t" on the 32-bit microsecond timer. */
static bool due(uint32_t now, uint32_t t) { return (int32_t)(now - t) >= 0; }

static void send(nd_core_t *c, uint8_t type, const void *body, size_t len) {
    uint8_t wire[ND_MAX_ENCODED + 1];
    size_t n = nd_frame_encode(type, c->tx_seq++, body, len, wire);
    hal_uart_write(wire, n);
}

static void send_error(nd_core_t *c, uint8_t code, uint8_t severity, uint32_t detail) {
    nd_error_t e = {code, severity, detail};
    send(c, ND_MSG_ERROR, &e, sizeof e);
}

static void send_param(nd_core_t *c, uint8_t id, float value, uint8_t status) {
    nd_param_value_t v = {id, value, status};
    send(c, ND_MSG_PARAM_VALUE, &v, sizeof v);
}

static void stop_motors(nd_core_t *c, bool brake) {
    memset(&c->cmd, 0, sizeof c->cmd);
    c->moving = false;
    c->braking = brake;
    nd_pid_reset(&c->pid);
    if (brake) {
        hal_motor_brake_all();
    } else {
        for (unsigned i = 0; i < c->board.wheels; i++) hal_motor_set(i, 0.0f);
    }
}

static float limit(float v, float max) {
    if (!isfinite(v)) return 0.0f;
    return v > max ? max : (v < -max ? -max : v);
}

static void on_velocity(nd_core_t *c, const nd_velocity_t *v, uint32_t now) {
    if (c->estop) return; /* latched: VELOCITY ignored until RESET */
    /* the firmware's own limits: what the wheels can do at full duty with these parameters */
    const float r = c->params.value[ND_PARAM_WHEEL_RADIUS];
    const float vmax = c->board.wheel_max_rad_s * r;
    const float lever = c->board.kinematics == ND_KIN_OMNI ? c->params.value[ND_PARAM_OMNI_RADIUS]
                                                          : 0.5f * c->params.value[ND_PARAM_TRACK_WIDTH];
    c->cmd.vx = limit(v->vx, vmax);
    c->cmd.vy = c->board.kinematics == ND_KIN_OMNI ? limit(v->vy, vmax) : 0.0f;
    c->cmd.wz = limit(v->wz, vmax / lever);
    c->last_cmd_us = now;
    c->watchdog_stop = false;
    c->moving = c->cmd.vx != 0.0f || c->cmd.vy != 0.0f || c->cmd.wz != 0.0f;
    if (c->moving) c->braking = false;
}

static void on_reset(nd_core_t *c, uint8_t mode) {
    /* re-arming: the latch and the stop bits clear, the held command is zero; nothing moves until
     * the host sends a fresh VELOCITY */
    c->estop = false;
    c->watchdog_stop = false;
    c->motor_fault = false;
    stop_motors(c, false);
    if (mode == ND_RESET_ZERO_ENCODERS || mode == ND_RESET_REBOOT) nd_encoders_zero(&c->enc);
    if (mode == ND_RESET_REBOOT) {
        c->reboot_requested = true;
        hal_reboot();
    }
}

static void on_frame(void *ctx, const nd_frame_t *f) {
    nd_core_t *c = ctx;
    const uint32_t now = hal_micros();
    switch (f->type) {
    case ND_MSG_VELOCITY: {
        nd_velocity_t v;
        memcpy(&v, f->body, sizeof v);
        on_velocity(c, &v, now);
        break;
    }
    case ND_MSG_HEARTBEAT: /* the host is alive, no motion wanted: does NOT feed the watchdog */
        break;
    case ND_MSG_ESTOP:
        c->estop = true;
        stop_motors(c, true);
        break;
    case ND_MSG_RESET: {
        nd_reset_t r;
        memcpy(&r, f->body, sizeof r);
        on_reset(c, r.mode);
        break;
    }
    case ND_MSG_PARAM_GET: {
        nd_param_get_t g;
        float value = 0.0f;
        memcpy(&g, f->body, sizeof g);
        uint8_t status = nd_params_get(&c->params, g.id, &value);
        send_param(c, g.id, value, status);
        break;
    }
    case ND_MSG_PARAM_SET: {
        nd_param_set_t s;
        memcpy(&s, f->body, sizeof s);
        uint8_t status = nd_params_set(&c->params, s.id, s.value);
        float now_value = 0.0f;
        nd_params_get(&c->params, s.id, &now_value);
        send_param(c, s.id, now_value, status);
        break;
    }
    case ND_MSG_PARAM_SAVE: {
        uint8_t status = nd_params_save(&c->params);
        send_param(c, ND_PARAM_SAVE_ALL, (float)(ND_PARAM_COUNT - 1), status);
        break;
    }
    default: /* a known type the base does not take (TELEMETRY, PARAM_VALUE, ERROR) */
        send_error(c, ND_ERR_UNKNOWN_MESSAGE, ND_SEV_WARNING, f->type);
        break;
    }
}

void nd_core_init(nd_core_t *c, const nd_board_t *board, const nd_geometry_t *geometry) {
    memset(c, 0, sizeof *c);
    c->board = *board;
    nd_params_defaults(&c->params, geometry);
    nd_params_load(&c->params);
    nd_rx_init(&c->rx);
    nd_encoders_init(&c->enc, board);
    nd_pid_reset(&c->pid);
    c->accel[2] = 9.81f;
    const uint32_t now = hal_micros();
    c->next_control_us = c->next_imu_us = c->next_telemetry_us = c->last_control_us = now;
    c->last_bad_report_us = now;
    stop_motors(c, false);
}

static void link_rx(nd_core_t *c) {
    uint8_t buf[128];
    size_t n;
    while ((n = hal_uart_read(buf, sizeof buf)) > 0) nd_rx_feed(&c->rx, buf, n, on_frame, c);
}

static void watchdog(nd_core_t *c, uint32_t now) {
    const uint32_t timeout_us = (uint32_t)(c->params.value[ND_PARAM_CMD_TIMEOUT] * 1e6f);
    if (c->moving && due(now, c->last_cmd_us + timeout_us)) {
        stop_motors(c, true); /* the host is gone: stop now, not coast */
        c->watchdog_stop = true;
        send_error(c, ND_ERR_WATCHDOG, ND_SEV_WARNING, (now - c->last_cmd_us) / 1000u);
    }
}

static void control(nd_core_t *c, uint32_t now) {
    const float dt = (float)(now - c->last_control_us) * 1e-6f;
    c->last_control_us = now;
    nd_encoders_update(&c->enc, &c->board, &c->params, dt);

    /* obstacle stop: an IR sensor holds forward motion off; reverse and turning stay allowed */
    const uint8_t ir = hal_ir_bits();
    const bool enabled = c->params.value[ND_PARAM_OBSTACLE_STOP_ENABLE] >= 0.5f;
    c->obstacle_stop = enabled && ir != 0 && (c->obstacle_stop || c->cmd.vx > 0.0f);
    const float vx = c->obstacle_stop && c->cmd.vx > 0.0f ? 0.0f : c->cmd.vx;

    if (c->estop || c->braking) return; /* motors stay braked */
    float target[ND_MAX_WHEELS];
    nd_inverse_kinematics(&c->board, &c->params, vx, c->cmd.vy, c->cmd.wz, target);
    nd_pid_step(&c->pid, &c->board, &c->params, target, c->enc.speed, dt);
    for (unsigned i = 0; i < c->board.wheels; i++) hal_motor_set(i, c->pid.duty[i]);
}

static void imu(nd_core_t *c) {
    float gz, acc[3];
    int err = hal_imu_read(&gz, acc);
    if (err != 0) {
        if (!c->imu_fault) send_error(c, ND_ERR_IMU_FAULT, ND_SEV_ERROR, (uint32_t)err);
        c->imu_fault = true;
        return;
    }
    c->imu_fault = false;
    c->gyro_sum += gz;
    c->gyro_n++;
    c->gyro_last = gz;
    memcpy(c->accel, acc, sizeof acc);
}

static void telemetry(nd_core_t *c, uint32_t now) {
    nd_telemetry_t t;
    t.mcu_us = now;
    for (unsigned i = 0; i < 4; i++) t.enc[i] = i < c->board.wheels ? c->enc.count[i] : 0;
    /* the MEAN yaw rate over the period (the host multiplies it by the frame interval); a period
     * without a sample repeats the last one */
    t.gyro_z = c->gyro_n ? c->gyro_sum / (float)c->gyro_n : c->gyro_last;
    c->gyro_sum = 0.0f;
    c->gyro_n = 0;
    t.accel_x = c->accel[0];
    t.accel_y = c->accel[1];
    t.accel_z = c->accel[2];
    t.ir_bits = hal_ir_bits();
    t.battery_mv = hal_battery_mv();
    uint16_t s = 0;
    if (c->estop) s |= ND_STATUS_ESTOP_LATCHED;
    if (c->obstacle_stop) s |= ND_STATUS_OBSTACLE_STOP;
    if (c->watchdog_stop) s |= ND_STATUS_WATCHDOG_STOP;
    if (c->motor_fault) s |= ND_STATUS_MOTOR_FAULT;
    if (c->imu_fault) s |= ND_STATUS_IMU_FAULT;
    if ((float)t.battery_mv < c->params.value[ND_PARAM_BATTERY_CUTOFF] * 1000.0f) s |= ND_STATUS_LOW_BATTERY;
    if (!c->params.from_flash) s |= ND_STATUS_PARAMS_DEFAULT;
    t.status = s;
    send(c, ND_MSG_TELEMETRY, &t, sizeof t);
    c->telemetry_sent++;
}

void nd_core_step(nd_core_t *c) {
    link_rx(c);
    uint32_t now = hal_micros();
    watchdog(c, now);
    if (due(now, c->next_imu_us)) {
        c->next_imu_us = now + ND_IMU_PERIOD_US;
        imu(c);
    }
    if (due(now, c->next_control_us)) {
        c->next_control_us = now + ND_CONTROL_PERIOD_US;
        control(c, now);
    }
    if (due(now, c->next_telemetry_us)) {
        const uint32_t period = (uint32_t)(1e6f / c->params.value[ND_PARAM_TELEMETRY_RATE]);
        /* keep the rate on average, but never burst to catch up after a stall */
        c->next_telemetry_us += period;
        if (due(now, c->next_telemetry_us)) c->next_telemetry_us = now + period;
        telemetry(c, now);
    }
    if (due(now, c->last_bad_report_us + ND_BAD_FRAME_REPORT_US)) {
        /* one glitch is not worth an ERROR (the host turns ERRORs into faults): report the
         * second's drops only when they exceed the host's own DEGRADED threshold of 5 % */
        const uint32_t bad = nd_rx_bad(&c->rx) - c->bad_reported;
        const uint32_t good = c->rx.good - c->good_reported;
        if (bad * 20u > bad + good) send_error(c, ND_ERR_BAD_FRAME, ND_SEV_WARNING, bad);
        c->bad_reported += bad;
        c->good_reported += good;
        c->last_bad_report_us = now;
    }
}
