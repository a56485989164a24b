#include "nd_params.h"

#include <math.h>
#include <string.h>

#include "hal.h"

#define RECORD_MAGIC 0x4E445052u /* "NDPR" */

typedef struct ND_PACKED {
    uint32_t magic;
    uint16_t version; /* protocol version the ids belong to */
    uint16_t count;   /* ND_PARAM_COUNT when written */
    float value[ND_PARAM_COUNT];
    uint16_t crc; /* CRC-16 of everything before it */
} record_t;

static const float RANGE[ND_PARAM_COUNT][2] = {
    [ND_PARAM_WHEEL_RADIUS] = {0.005f, 0.5f},
    [ND_PARAM_TRACK_WIDTH] = {0.02f, 2.0f},
    [ND_PARAM_WHEEL_BASE] = {0.0f, 2.0f},
    [ND_PARAM_TICKS_PER_REV] = {1.0f, 1e6f},
    [ND_PARAM_PID_KP] = {0.0f, 1e3f},
    [ND_PARAM_PID_KI] = {0.0f, 1e3f},
    [ND_PARAM_PID_KD] = {0.0f, 1e3f},
    [ND_PARAM_CMD_TIMEOUT] = {0.05f, 2.0f},
    [ND_PARAM_TELEMETRY_RATE] = {10.0f, 200.0f},
    [ND_PARAM_OBSTACLE_STOP_ENABLE] = {0.0f, 1.0f},
    [ND_PARAM_OMNI_RADIUS] = {0.02f, 2.0f},
    [ND_PARAM_BATTERY_CUTOFF] = {0.0f, 60.0f},
};

void nd_params_defaults(nd_params_t *p, const nd_geometry_t *g) {
    memset(p, 0, sizeof *p);
    p->value[ND_PARAM_WHEEL_RADIUS] = g->wheel_radius;
    p->value[ND_PARAM_TRACK_WIDTH] = g->track_width;
    p->value[ND_PARAM_WHEEL_BASE] = g->wheel_base;
    p->value[ND_PARAM_TICKS_PER_REV] = g->ticks_per_rev;
    p->value[ND_PARAM_PID_KP] = 1.2f;
    p->value[ND_PARAM_PID_KI] = 8.0f;
    p->value[ND_PARAM_PID_KD] = 0.0f;
    p->value[ND_PARAM_CMD_TIMEOUT] = 0.2f;
    p->value[ND_PARAM_TELEMETRY_RATE] = 50.0f;
    p->value[ND_PARAM_OBSTACLE_STOP_ENABLE] = 1.0f;
    p->value[ND_PARAM_OMNI_RADIUS] = g->omni_radius;
    p->value[ND_PARAM_BATTERY_CUTOFF] = g->battery_cutoff;
    p->from_flash = false;
}

static bool valid(uint8_t id, float v) {
    return id >= 1 && id < ND_PARAM_COUNT && isfinite(v) && v >= RANGE[id][0] && v <= RANGE[id][1];
}

bool nd_params_load(nd_params_t *p) {
    record_t r;
    if (hal_flash_read(&r, sizeof r) != 0) return false;
    if (r.magic != RECORD_MAGIC || r.version != ND_PROTOCOL_VERSION || r.count != ND_PARAM_COUNT) return false;
    if (nd_crc16((const uint8_t *)&r, offsetof(record_t, crc)) != r.crc) return false;
    for (uint8_t id = 1; id < ND_PARAM_COUNT; id++)
        if (!valid(id, r.value[id])) return false; /* a record from other ranges: keep defaults */
    memcpy(p->value, r.value, sizeof p->value);
    p->from_flash = true;
    return true;
}

uint8_t nd_params_set(nd_params_t *p, uint8_t id, float value) {
    if (id < 1 || id >= ND_PARAM_COUNT) return ND_PARAM_UNKNOWN_ID;
    if (!valid(id, value)) return ND_PARAM_OUT_OF_RANGE;
    p->value[id] = value;
    return ND_PARAM_OK;
}

uint8_t nd_params_get(const nd_params_t *p, uint8_t id, float *value) {
    if (id < 1 || id >= ND_PARAM_COUNT) return ND_PARAM_UNKNOWN_ID;
    *value = p->value[id];
    return ND_PARAM_OK;
}

uint8_t nd_params_save(nd_params_t *p) {
    record_t r, back;
    memset(&r, 0, sizeof r);
    r.magic = RECORD_MAGIC;
    r.version = ND_PROTOCOL_VERSION;
    r.count = ND_PARAM_COUNT;
    memcpy(r.value, p->value, sizeof r.value);
    r.crc = nd_crc16((const uint8_t *)&r, offsetof(record_t, crc));
    if (hal_flash_write(&r, sizeof r) != 0) return ND_PARAM_FLASH_ERROR;
    if (hal_flash_read(&back, sizeof back) != 0 || memcmp(&r, &back, sizeof r) != 0) return ND_PARAM_FLASH_ERROR;
    p->from_flash = true;
    return ND_PARAM_OK;
}
