/* Motor control: inverse kinematics with the *parameters*, encoder odometry (16-bit timer counts
 * extended to 32 bits, wheel speeds), and one speed PID per wheel. */
#ifndef NAVDECK_CONTROL_H
#define NAVDECK_CONTROL_H

#include <stdint.h>

#include "nd_params.h"

#define ND_MAX_WHEELS 4

typedef enum { ND_KIN_DIFF = 0, ND_KIN_SKID = 1, ND_KIN_OMNI = 2 } nd_kinematics_t;

typedef struct {
    nd_kinematics_t kinematics;
    unsigned wheels;       /* 2 (diff: L, R) or 4 (skid: FL, RL, FR, RR; omni: front, left, rear, right) */
    float wheel_max_rad_s; /* motor no-load wheel speed at full duty: feed-forward and PID scale */
} nd_board_t;

typedef struct {
    uint16_t last_raw[ND_MAX_WHEELS];
    int32_t count[ND_MAX_WHEELS]; /* cumulative, wraps like int32 (the host unwraps) */
    float speed[ND_MAX_WHEELS];   /* rad/s, low-pass filtered */
} nd_encoders_t;

typedef struct {
    float integral[ND_MAX_WHEELS];
    float last_error[ND_MAX_WHEELS];
    float duty[ND_MAX_WHEELS];
} nd_pid_t;

/* Wheel angular speeds (rad/s, profile order) for a body twist, with the parameters' geometry. */
void nd_inverse_kinematics(const nd_board_t *b, const nd_params_t *p, float vx, float vy, float wz,
                           float wheel_rad_s[ND_MAX_WHEELS]);

void nd_encoders_init(nd_encoders_t *e, const nd_board_t *b);
/* Sample the encoder timers: extend counts, update speeds over dt seconds. */
void nd_encoders_update(nd_encoders_t *e, const nd_board_t *b, const nd_params_t *p, float dt);
/* Zero the cumulative counts (RESET mode 1). */
void nd_encoders_zero(nd_encoders_t *e);

void nd_pid_reset(nd_pid_t *c);
/* One control step: duty per wheel from targets and measured speeds (rad/s), over dt seconds.
 * The error is scaled by wheel_max_rad_s, so the gains are "duty per fraction of full speed"
 * and the defaults (1.2, 8, 0) suit any motor; a feed-forward term target/max carries the bulk. */
void nd_pid_step(nd_pid_t *c, const nd_board_t *b, const nd_params_t *p, const float target[ND_MAX_WHEELS],
                 const float measured[ND_MAX_WHEELS], float dt);

#endif
