/* Host implementation of hal.h: the UART is a pseudo-terminal (a stable symlink points at its
 * slave, like /dev/serial/by-id), the motors and sensors are a simulated plant, the flash is a file. */
#ifndef NAVDECK_HAL_HOST_H
#define NAVDECK_HAL_HOST_H

#include <stdbool.h>

#include "plant.h"

typedef struct {
    const char *link;       /* symlink clients open */
    const char *flash_path; /* NULL: no flash (PARAM_SAVE answers FLASH_ERROR) */
    nd_plant_t plant;
    int master, slave;      /* -1 while unplugged */
    bool reboot;            /* hal_reboot was called */
    double boot_s;          /* monotonic time of the (last) boot: hal_micros counts from it */
    int imu_error;          /* non-zero: hal_imu_read fails with it (fault injection) */
    uint8_t ir_bits;
} hal_host_t;

extern hal_host_t g_host;

double host_now_s(void);
int host_plug(void);   /* create a pty and point the link at it; 0 ok */
void host_unplug(void); /* close it and remove the link: clients see the device vanish */
/* Wait up to timeout_s for host bytes (returns early when some arrive). */
void host_wait_input(double timeout_s);

#endif
