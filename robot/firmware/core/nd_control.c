#include "nd_control.h"

#include <string.h>

#include "hal.h"

void nd_inverse_kinematics(const nd_board_t *b, const nd_params_t *p, float vx, float vy, float wz,
                           float w[ND_MAX_WHEELS]) {
    const float r = p->value[ND_PARAM_WHEEL_RADIUS];
    float rim[ND_MAX_WHEELS] = {0};
    if (b->kinematics == ND_KIN_OMNI) {
        /* wheel i at angle a_i (front 0, left pi/2, rear pi, right -pi/2) rolls tangentially:
         * rim = -sin(a) vx + cos(a) vy + R wz (robot/kinematics.py omni_inverse) */
        const float rw = p->value[ND_PARAM_OMNI_RADIUS] * wz;
        rim[0] = vy + rw;
        rim[1] = -vx + rw;
        rim[2] = -vy + rw;
        rim[3] = vx + rw;
    } else {
        const float half = wz * p->value[ND_PARAM_TRACK_WIDTH] * 0.5f;
        const float left = vx - half, right = vx + half; /* vy is ignored: skid and diff cannot */
        if (b->wheels == 2) {
            rim[0] = left;
            rim[1] = right;
        } else {
            rim[0] = rim[1] = left;
            rim[2] = rim[3] = right;
        }
    }
    for (unsigned i = 0; i < ND_MAX_WHEELS; i++) w[i] = i < b->wheels ? rim[i] / r : 0.0f;
}

void nd_encoders_init(nd_encoders_t *e, const nd_board_t *b) {
    memset(e, 0, sizeof *e);
    for (unsigned i = 0; i < b->wheels; i++) e->last_raw[i] = hal_encoder_raw(i);
}

void nd_encoders_update(nd_encoders_t *e, const nd_board_t *b, const nd_params_t *p, float dt) {
    const float rad_per_tick = 6.28318531f / p->value[ND_PARAM_TICKS_PER_REV];
    for (unsigned i = 0; i < b->wheels; i++) {
        uint16_t raw = hal_encoder_raw(i);
        int16_t delta = (int16_t)(uint16_t)(raw - e->last_raw[i]); /* < 32768 counts per sample */
        e->last_raw[i] = raw;
        e->count[i] = (int32_t)((uint32_t)e->count[i] + (uint32_t)(int32_t)delta);
        if (dt > 0.0f) {
            /* one-pole low-pass: 1320-count encoders resolve ~0.5 rad/s per 10 ms sample */
            const float raw_speed = (float)delta * rad_per_tick / dt;
            e->speed[i] += 0.5f * (raw_speed - e->speed[i]);
        }
    }
}

void nd_encoders_zero(nd_encoders_t *e) { memset(e->count, 0, sizeof e->count); }

void nd_pid_reset(nd_pid_t *c) { memset(c, 0, sizeof *c); }

static float clampf(float v, float lo, float hi) { return v < lo ? lo : (v > hi ? hi : v); }

void nd_pid_step(nd_pid_t *c, const nd_board_t *b, const nd_params_t *p, const float target[ND_MAX_WHEELS],
                 const float measured[ND_MAX_WHEELS], float dt) {
    const float kp = p->value[ND_PARAM_PID_KP], ki = p->value[ND_PARAM_PID_KI], kd = p->value[ND_PARAM_PID_KD];
    const float scale = 1.0f / b->wheel_max_rad_s;
    for (unsigned i = 0; i < b->wheels; i++) {
        if (target[i] == 0.0f && c->duty[i] == 0.0f) {
            c->integral[i] = c->last_error[i] = 0.0f; /* at rest: no windup from encoder jitter */
            continue;
        }
        const float err = (target[i] - measured[i]) * scale;
        const float deriv = dt > 0.0f ? (err - c->last_error[i]) / dt : 0.0f;
        c->last_error[i] = err;
        const float ff = target[i] * scale;
        float duty = ff + kp * err + ki * (c->integral[i] + err * dt) + kd * deriv;
        if (duty > -1.0f && duty < 1.0f) c->integral[i] += err * dt; /* anti-windup: freeze when saturated */
        duty = clampf(duty, -1.0f, 1.0f);
        if (target[i] == 0.0f && (duty * c->duty[i] < 0.0f || (measured[i] > -0.5f && measured[i] < 0.5f)))
            duty = 0.0f; /* stopping: never drive backwards through zero, coast the last counts */
        c->duty[i] = duty;
    }
}
