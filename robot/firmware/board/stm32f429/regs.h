/* The few STM32F429 registers the board layer uses (RM0090), as plain addresses: no vendor headers
 * needed to build. Offsets are in bytes from each peripheral's base. */
#ifndef NAVDECK_STM32F429_REGS_H
#define NAVDECK_STM32F429_REGS_H

#include <stdint.h>

#define REG(addr) (*(volatile uint32_t *)(uintptr_t)(addr))

/* RCC */
#define RCC_BASE 0x40023800u
#define RCC_CR REG(RCC_BASE + 0x00)
#define RCC_PLLCFGR REG(RCC_BASE + 0x04)
#define RCC_CFGR REG(RCC_BASE + 0x08)
#define RCC_AHB1ENR REG(RCC_BASE + 0x30)
#define RCC_APB1ENR REG(RCC_BASE + 0x40)
#define RCC_APB2ENR REG(RCC_BASE + 0x44)

/* FLASH interface */
#define FLASH_BASE_R 0x40023C00u
#define FLASH_ACR REG(FLASH_BASE_R + 0x00)
#define FLASH_KEYR REG(FLASH_BASE_R + 0x04)
#define FLASH_SR REG(FLASH_BASE_R + 0x0C)
#define FLASH_CR REG(FLASH_BASE_R + 0x10)

/* GPIO ports A..E */
#define GPIO_BASE(port) (0x40020000u + 0x400u * (uint32_t)(port))
#define GPIO_MODER(p) REG(GPIO_BASE(p) + 0x00)
#define GPIO_OSPEEDR(p) REG(GPIO_BASE(p) + 0x08)
#define GPIO_PUPDR(p) REG(GPIO_BASE(p) + 0x0C)
#define GPIO_IDR(p) REG(GPIO_BASE(p) + 0x10)
#define GPIO_BSRR(p) REG(GPIO_BASE(p) + 0x18)
#define GPIO_AFR(p, i) REG(GPIO_BASE(p) + 0x20 + 4u * (uint32_t)(i))
#define GPIO_OTYPER(p) REG(GPIO_BASE(p) + 0x04)
enum { PORT_A, PORT_B, PORT_C, PORT_D, PORT_E };

/* USART1 (APB2) */
#define USART1_BASE 0x40011000u
#define USART1_SR REG(USART1_BASE + 0x00)
#define USART1_DR_ADDR (USART1_BASE + 0x04)
#define USART1_BRR REG(USART1_BASE + 0x08)
#define USART1_CR1 REG(USART1_BASE + 0x0C)
#define USART1_CR3 REG(USART1_BASE + 0x14)

/* DMA2: USART1_RX = stream 2 channel 4, USART1_TX = stream 7 channel 4 */
#define DMA2_BASE 0x40026400u
#define DMA2_LISR REG(DMA2_BASE + 0x00)
#define DMA2_HISR REG(DMA2_BASE + 0x04)
#define DMA2_LIFCR REG(DMA2_BASE + 0x08)
#define DMA2_HIFCR REG(DMA2_BASE + 0x0C)
#define DMA2_S_CR(s) REG(DMA2_BASE + 0x10 + 0x18u * (s))
#define DMA2_S_NDTR(s) REG(DMA2_BASE + 0x14 + 0x18u * (s))
#define DMA2_S_PAR(s) REG(DMA2_BASE + 0x18 + 0x18u * (s))
#define DMA2_S_M0AR(s) REG(DMA2_BASE + 0x1C + 0x18u * (s))
#define DMA2_S_FCR(s) REG(DMA2_BASE + 0x24 + 0x18u * (s))

/* General purpose / advanced timers */
#define TIM1_BASE 0x40010000u
#define TIM2_BASE 0x40000000u
#define TIM3_BASE 0x40000400u
#define TIM4_BASE 0x40000800u
#define TIM5_BASE 0x40000C00u
#define TIM_CR1(t) REG((t) + 0x00)
#define TIM_SMCR(t) REG((t) + 0x08)
#define TIM_EGR(t) REG((t) + 0x14)
#define TIM_CCMR1(t) REG((t) + 0x18)
#define TIM_CCMR2(t) REG((t) + 0x1C)
#define TIM_CCER(t) REG((t) + 0x20)
#define TIM_CNT(t) REG((t) + 0x24)
#define TIM_PSC(t) REG((t) + 0x28)
#define TIM_ARR(t) REG((t) + 0x2C)
#define TIM_CCR(t, ch) REG((t) + 0x34 + 4u * ((ch) - 1u))
#define TIM_BDTR(t) REG((t) + 0x44)

/* I2C1 (APB1) */
#define I2C1_BASE 0x40005400u
#define I2C1_CR1 REG(I2C1_BASE + 0x00)
#define I2C1_CR2 REG(I2C1_BASE + 0x04)
#define I2C1_DR REG(I2C1_BASE + 0x10)
#define I2C1_SR1 REG(I2C1_BASE + 0x14)
#define I2C1_SR2 REG(I2C1_BASE + 0x18)
#define I2C1_CCR REG(I2C1_BASE + 0x1C)
#define I2C1_TRISE REG(I2C1_BASE + 0x20)

/* ADC1 */
#define ADC1_BASE 0x40012000u
#define ADC1_SR REG(ADC1_BASE + 0x00)
#define ADC1_CR2 REG(ADC1_BASE + 0x08)
#define ADC1_SMPR1 REG(ADC1_BASE + 0x0C)
#define ADC1_SQR3 REG(ADC1_BASE + 0x34)
#define ADC1_DR REG(ADC1_BASE + 0x4C)
#define ADC_CCR REG(0x40012304u)

/* Cortex-M4 core */
#define SYST_CSR REG(0xE000E010u)
#define SYST_RVR REG(0xE000E014u)
#define SYST_CVR REG(0xE000E018u)
#define SCB_CPACR REG(0xE000ED88u)
#define SCB_AIRCR REG(0xE000ED0Cu)

#endif
