/* The portable base firmware: link (frame handling), command watchdog, e-stop latch, motor
 * control, IMU averaging, obstacle stop, telemetry and parameters, behind hal.h. A board calls
 * nd_core_init once and nd_core_step from its 1 ms tick (or a tight loop): the core runs each job
 * at its own period on hal_micros(), as the FreeRTOS tasks of docs/serial-protocol.md section 5. */
#ifndef NAVDECK_CORE_H
#define NAVDECK_CORE_H

#include <stdbool.h>
#include <stdint.h>

#include "navdeck_protocol.h"
#include "nd_control.h"
#include "nd_params.h"

#define ND_CONTROL_PERIOD_US 10000u /* MotorControlTask + ObstacleTask: 10 ms */
#define ND_IMU_PERIOD_US 5000u      /* IMUTask: 5 ms */
#define ND_BAD_FRAME_REPORT_US 1000000u

typedef struct {
    nd_board_t board;
    nd_params_t params;
    nd_encoders_t enc;
    nd_pid_t pid;
    nd_rx_t rx;
    uint8_t tx_seq;

    /* command state */
    nd_velocity_t cmd;     /* held VELOCITY, after the firmware's clamp */
    uint32_t last_cmd_us;  /* when the last VELOCITY arrived */
    bool moving;           /* the held command is non-zero */
    bool estop;            /* ESTOP_LATCHED */
    bool watchdog_stop;    /* WATCHDOG_STOP */
    bool braking;          /* e-stop or watchdog: motors held braked until a fresh command or RESET */
    bool obstacle_stop;    /* OBSTACLE_STOP */
    bool motor_fault;
    bool imu_fault;

    /* IMU accumulation between two TELEMETRY frames */
    float gyro_sum, gyro_last;
    uint32_t gyro_n;
    float accel[3];

    uint32_t next_control_us, next_imu_us, next_telemetry_us, last_bad_report_us;
    uint32_t last_control_us;
    uint32_t bad_reported, good_reported; /* receiver counts at the last BAD_FRAME check */
    uint32_t telemetry_sent;
    bool reboot_requested; /* RESET mode 2 on a host whose hal_reboot returns */
} nd_core_t;

void nd_core_init(nd_core_t *c, const nd_board_t *board, const nd_geometry_t *geometry);
void nd_core_step(nd_core_t *c);

#endif
