/* The hardware interface the portable firmware core runs on. A board provides these functions
 * (board/stm32f429/ on the robot, host/hal_host.c on a PC with a simulated plant); the core never
 * touches a register or an OS call itself. All functions are called from the core's single
 * context (the 1 ms loop), never from interrupts. */
#ifndef NAVDECK_HAL_H
#define NAVDECK_HAL_H

#include <stddef.h>
#include <stdint.h>

/* Free-running microsecond timer (wraps at 2^32, ~71 min). */
uint32_t hal_micros(void);

/* UART: non-blocking. read returns the bytes received since the last call (at most cap); write
 * queues bytes for transmission and drops what does not fit (a UART never blocks the loop). */
size_t hal_uart_read(uint8_t *buf, size_t cap);
void hal_uart_write(const uint8_t *buf, size_t n);

/* Quadrature encoder timer counter of wheel i (profile wheel order), forward rolling counts up.
 * 16 bits are enough: the core extends it to 32 bits, read at >= 100 Hz. */
uint16_t hal_encoder_raw(unsigned wheel);

/* Motor drive of wheel i: duty in [-1, 1], sign = direction (forward rolling positive). */
void hal_motor_set(unsigned wheel, float duty);
/* All motors off with the H-bridges braking (e-stop). The next hal_motor_set releases the brake. */
void hal_motor_brake_all(void);

/* IMU: yaw rate (rad/s CCW) and acceleration (m/s^2) in base_link. Returns 0, or an I2C error code. */
int hal_imu_read(float *gyro_z, float accel[3]);

/* IR obstacle inputs: bit i = sensor i (profile order) sees an obstacle. */
uint8_t hal_ir_bits(void);

/* Battery voltage in millivolts. */
uint16_t hal_battery_mv(void);

/* Parameter flash sector: read n bytes of the stored record (0 = ok), erase + write it (0 = ok). */
int hal_flash_read(void *buf, size_t n);
int hal_flash_write(const void *buf, size_t n);

/* Reset the MCU (NVIC_SystemReset on the board). May return on hosts that restart the core. */
void hal_reboot(void);

#endif
