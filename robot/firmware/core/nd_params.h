/* Parameter store: the PARAM_* values in RAM, their ranges, and a CRC-checked flash record written
 * only by an explicit PARAM_SAVE (PARAM_SET alone never touches flash: no wear from calibration
 * sweeps, and a bad value is undone by a reboot). */
#ifndef NAVDECK_PARAMS_H
#define NAVDECK_PARAMS_H

#include <stdbool.h>
#include <stdint.h>

#include "navdeck_protocol.h"

typedef struct {
    float value[ND_PARAM_COUNT]; /* index = parameter id; [0] unused */
    bool from_flash;             /* false: compiled/board defaults, PARAMS_DEFAULT status bit */
} nd_params_t;

/* Board defaults of the geometry (the rest have protocol defaults). */
typedef struct {
    float wheel_radius, track_width, wheel_base, ticks_per_rev, omni_radius, battery_cutoff;
} nd_geometry_t;

void nd_params_defaults(nd_params_t *p, const nd_geometry_t *g);
/* Load the flash record over the defaults if it is valid; returns true if it was. */
bool nd_params_load(nd_params_t *p);
/* PARAM_SET: validate and apply; returns an nd_param_status. */
uint8_t nd_params_set(nd_params_t *p, uint8_t id, float value);
/* PARAM_GET: returns ND_PARAM_OK and the value, or ND_PARAM_UNKNOWN_ID. */
uint8_t nd_params_get(const nd_params_t *p, uint8_t id, float *value);
/* PARAM_SAVE: write all values to flash and read them back; returns ND_PARAM_OK or FLASH_ERROR. */
uint8_t nd_params_save(nd_params_t *p);

#endif
