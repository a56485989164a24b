#include "plant.h"

#include <math.h>

void nd_plant_step(nd_plant_t *p, double dt) {
    if (dt <= 0.0) return;
    for (unsigned i = 0; i < p->wheels; i++) {
        /* braking shorts the motor: a 10 ms time constant to standstill */
        const double target = p->brake ? 0.0 : p->duty[i] * p->motor_max_rad_s;
        const double tau = p->brake ? 0.01 : p->tau_s;
        const double a = 1.0 - exp(-dt / tau);
        const double before = p->speed[i];
        p->speed[i] += (target - p->speed[i]) * a;
        p->angle[i] += 0.5 * (before + p->speed[i]) * dt;
    }
    double rim[ND_MAX_WHEELS];
    for (unsigned i = 0; i < p->wheels; i++) rim[i] = p->speed[i] * p->wheel_radius;
    if (p->kinematics == ND_KIN_OMNI) { /* least-squares forward kinematics (robot/kinematics.py) */
        p->vx = (rim[3] - rim[1]) / 2.0;
        p->vy = (rim[0] - rim[2]) / 2.0;
        p->yaw_rate = (rim[0] + rim[1] + rim[2] + rim[3]) / (4.0 * p->omni_radius);
    } else {
        const double left = p->wheels == 2 ? rim[0] : 0.5 * (rim[0] + rim[1]);
        const double right = p->wheels == 2 ? rim[1] : 0.5 * (rim[2] + rim[3]);
        p->vx = 0.5 * (left + right);
        p->vy = 0.0;
        p->yaw_rate = (right - left) / p->track_width;
    }
}

uint16_t nd_plant_encoder(const nd_plant_t *p, unsigned wheel) {
    const double counts = floor(p->angle[wheel] / (2.0 * 3.14159265358979323846) * p->ticks_per_rev);
    return (uint16_t)(int64_t)counts; /* the timer's 16-bit counter wraps */
}
