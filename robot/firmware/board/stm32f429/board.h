/* STM32F429 base board: clocks, pins and constants of the reference wiring (docs/hardware.md,
 * "Flashing the reference firmware"). Change the pin table here for another board. */
#ifndef NAVDECK_STM32F429_BOARD_H
#define NAVDECK_STM32F429_BOARD_H

#define SYSCLK_HZ 168000000u /* HSE 8 MHz -> PLL: M 8, N 336, P 2 (Q 7 for a 48 MHz USB clock) */
#define APB1_HZ (SYSCLK_HZ / 4u)
#define APB2_HZ (SYSCLK_HZ / 2u)
#define HSE_HZ 8000000u

#define BASE_BAUD 115200u
#define PWM_HZ 20000u /* TIM1, above hearing */

/* Parameter record: the last 128 KB sector of a 2 MB STM32F429ZI (sector 23, bank 2), so
 * erasing it never stalls code running from bank 1. On a 1 MB part use sector 11 (0x080E0000). */
#define PARAM_FLASH_ADDR 0x081E0000u
#define PARAM_FLASH_SNB 0x1Bu /* FLASH_CR.SNB encoding of sector 23: bank 2 (0x10) | 11 */

/* Robot: the seed robot's skid4 geometry (robot/profiles/skid4.toml); PARAM_SET + PARAM_SAVE
 * change it without rebuilding. */
#define ROBOT_KINEMATICS ND_KIN_SKID
#define ROBOT_WHEELS 4u
#define ROBOT_WHEEL_MAX_RAD_S 20.0f /* JGB37-520 at 12 V: ~190 rpm under load */
#define ROBOT_WHEEL_RADIUS 0.0325f
#define ROBOT_TRACK_WIDTH 0.19f
#define ROBOT_WHEEL_BASE 0.15f
#define ROBOT_TICKS_PER_REV 1320.0f
#define ROBOT_OMNI_RADIUS 0.25f
#define ROBOT_BATTERY_CUTOFF 10.5f

/* Battery: PC2 = ADC123_IN12 behind a 100k / 10k divider */
#define BATTERY_ADC_CHANNEL 12u
#define BATTERY_DIVIDER 11.0f

/* MPU6050 on I2C1 (PB6 SCL, PB7 SDA) */
#define MPU6050_ADDR 0x68u

#endif
