/* A simulated base for the host build: per-wheel DC motor (first-order speed response to duty,
 * brake), quadrature encoders on the TRUE geometry, and a gyro from the true body yaw rate. */
#ifndef NAVDECK_PLANT_H
#define NAVDECK_PLANT_H

#include <stdbool.h>
#include <stdint.h>

#include "nd_control.h"

typedef struct {
    nd_kinematics_t kinematics;
    unsigned wheels;
    double wheel_radius, track_width, omni_radius, ticks_per_rev; /* the true geometry */
    double motor_max_rad_s; /* no-load wheel speed at full duty (a bit below the board's nominal) */
    double tau_s;           /* motor speed time constant */
    double duty[ND_MAX_WHEELS];
    bool brake;
    double speed[ND_MAX_WHEELS]; /* wheel rad/s */
    double angle[ND_MAX_WHEELS]; /* wheel rad, cumulative */
    double yaw_rate;             /* body rad/s (what the gyro measures) */
    double vx, vy;               /* body m/s */
    double battery_v;
} nd_plant_t;

void nd_plant_step(nd_plant_t *p, double dt);
uint16_t nd_plant_encoder(const nd_plant_t *p, unsigned wheel);

#endif
