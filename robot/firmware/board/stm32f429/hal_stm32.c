/* hal.h on the STM32F429, register level: SysTick 1 ms tick + microsecond time, USART1 with DMA
 * in both directions (RX into a circular buffer the core drains, TX from a ring), TIM2..TIM5 as
 * quadrature encoder counters, TIM1 PWM + direction pins for four motor drivers, MPU6050 on I2C1
 * (polled, with time-outs), battery on ADC1, parameters in a flash sector. No interrupts but
 * SysTick: the core polls everything from its 1 ms loop. Pin table in board.h / docs/hardware.md. */
#include <string.h>

#include "board.h"
#include "hal.h"
#include "regs.h"

/* ---- clocks and tick -------------------------------------------------------------------------- */
static volatile uint32_t g_ms;

void SysTick_Handler(void) { g_ms++; }

static void clock_init(void) {
    RCC_CR |= 1u << 16; /* HSEON */
    while (!(RCC_CR & (1u << 17))) {
    }
    FLASH_ACR = 5u | (1u << 8) | (1u << 9) | (1u << 10); /* 5 wait states at 168 MHz, prefetch, caches */
    RCC_PLLCFGR = 8u | (336u << 6) | (0u << 16) | (1u << 22) | (7u << 24); /* M 8, N 336, P 2, HSE, Q 7 */
    RCC_CR |= 1u << 24; /* PLLON */
    while (!(RCC_CR & (1u << 25))) {
    }
    RCC_CFGR = (5u << 10) | (4u << 13) | 2u; /* APB1 /4, APB2 /2, SYSCLK = PLL */
    while (((RCC_CFGR >> 2) & 3u) != 2u) {
    }
    SYST_RVR = SYSCLK_HZ / 1000u - 1u;
    SYST_CVR = 0;
    SYST_CSR = 7u; /* core clock, interrupt, enable */
}

uint32_t hal_micros(void) {
    uint32_t ms, ticks;
    do { /* a tick between the two reads: read again */
        ms = g_ms;
        ticks = SYST_RVR - SYST_CVR;
    } while (ms != g_ms);
    return ms * 1000u + ticks / (SYSCLK_HZ / 1000000u);
}

/* ---- GPIO helpers ----------------------------------------------------------------------------- */
static void pin_mode(int port, unsigned pin, unsigned mode, unsigned af) {
    GPIO_MODER(port) = (GPIO_MODER(port) & ~(3u << (2 * pin))) | (mode << (2 * pin));
    GPIO_OSPEEDR(port) |= 2u << (2 * pin);
    if (mode == 2u) GPIO_AFR(port, pin / 8) = (GPIO_AFR(port, pin / 8) & ~(0xFu << (4 * (pin % 8)))) | (af << (4 * (pin % 8)));
}
#define MODE_IN 0u
#define MODE_OUT 1u
#define MODE_AF 2u
#define MODE_ANALOG 3u

static void pin_pull_up(int port, unsigned pin) {
    GPIO_PUPDR(port) = (GPIO_PUPDR(port) & ~(3u << (2 * pin))) | (1u << (2 * pin));
}

static void pin_write(int port, unsigned pin, int high) { GPIO_BSRR(port) = high ? (1u << pin) : (1u << (pin + 16)); }

/* ---- USART1 + DMA2 ---------------------------------------------------------------------------- */
#define RX_SIZE 512u
#define TX_SIZE 1024u
static uint8_t g_rx[RX_SIZE];
static uint32_t g_rx_tail;
static uint8_t g_tx[TX_SIZE];
static uint32_t g_tx_head, g_tx_tail, g_tx_busy; /* ring [tail, head); busy = bytes the DMA is sending */

static void uart_init(void) {
    pin_mode(PORT_A, 9, MODE_AF, 7);  /* PA9  USART1_TX */
    pin_mode(PORT_A, 10, MODE_AF, 7); /* PA10 USART1_RX */
    pin_pull_up(PORT_A, 10);
    USART1_BRR = (APB2_HZ + BASE_BAUD / 2u) / BASE_BAUD;
    USART1_CR3 = (1u << 6) | (1u << 7); /* DMAR, DMAT */
    USART1_CR1 = (1u << 13) | (1u << 3) | (1u << 2); /* UE, TE, RE */
    /* RX: stream 2 channel 4, peripheral -> memory, circular, byte-wide, memory increment */
    DMA2_S_CR(2) = 0;
    DMA2_LIFCR = 0x003D0000u;
    DMA2_S_PAR(2) = USART1_DR_ADDR;
    DMA2_S_M0AR(2) = (uint32_t)(uintptr_t)g_rx;
    DMA2_S_NDTR(2) = RX_SIZE;
    DMA2_S_CR(2) = (4u << 25) | (1u << 10) | (1u << 8) | (2u << 16) | 1u; /* CHSEL 4, MINC, CIRC, PL high, EN */
}

size_t hal_uart_read(uint8_t *buf, size_t cap) {
    const uint32_t head = RX_SIZE - DMA2_S_NDTR(2); /* where the DMA writes next */
    size_t n = 0;
    while (g_rx_tail != head && n < cap) {
        buf[n++] = g_rx[g_rx_tail];
        g_rx_tail = (g_rx_tail + 1u) % RX_SIZE;
    }
    return n;
}

static void tx_kick(void) {
    if (g_tx_busy) {
        if (!(DMA2_HISR & (1u << 27))) return; /* TCIF7: still sending */
        DMA2_HIFCR = 0x0F400000u;
        g_tx_tail = (g_tx_tail + g_tx_busy) % TX_SIZE;
        g_tx_busy = 0;
    }
    if (g_tx_tail == g_tx_head) return;
    /* one contiguous run up to the end of the ring; the rest goes with the next kick */
    const uint32_t run = g_tx_head > g_tx_tail ? g_tx_head - g_tx_tail : TX_SIZE - g_tx_tail;
    DMA2_S_CR(7) = 0;
    DMA2_HIFCR = 0x0F400000u;
    DMA2_S_PAR(7) = USART1_DR_ADDR;
    DMA2_S_M0AR(7) = (uint32_t)(uintptr_t)&g_tx[g_tx_tail];
    DMA2_S_NDTR(7) = run;
    DMA2_S_CR(7) = (4u << 25) | (1u << 10) | (1u << 6) | (1u << 16) | 1u; /* CHSEL 4, MINC, M->P, PL medium, EN */
    g_tx_busy = run;
}

void hal_uart_write(const uint8_t *buf, size_t n) {
    tx_kick();
    const uint32_t used = (g_tx_head + TX_SIZE - g_tx_tail) % TX_SIZE;
    if (n > TX_SIZE - 1u - used) return; /* no room for the whole frame: drop it, never half of it */
    for (size_t i = 0; i < n; i++) {
        g_tx[g_tx_head] = buf[i];
        g_tx_head = (g_tx_head + 1u) % TX_SIZE;
    }
    tx_kick();
}

/* ---- encoders: TIM2 (PA15, PB3), TIM3 (PB4, PB5), TIM4 (PD12, PD13), TIM5 (PA0, PA1) ------------ */
static const uint32_t ENC_TIM[4] = {TIM2_BASE, TIM3_BASE, TIM4_BASE, TIM5_BASE};

static void encoders_init(void) {
    pin_mode(PORT_A, 15, MODE_AF, 1);
    pin_mode(PORT_B, 3, MODE_AF, 1);
    pin_mode(PORT_B, 4, MODE_AF, 2);
    pin_mode(PORT_B, 5, MODE_AF, 2);
    pin_mode(PORT_D, 12, MODE_AF, 2);
    pin_mode(PORT_D, 13, MODE_AF, 2);
    pin_mode(PORT_A, 0, MODE_AF, 2);
    pin_mode(PORT_A, 1, MODE_AF, 2);
    for (unsigned i = 0; i < 4; i++) {
        const uint32_t t = ENC_TIM[i];
        TIM_CCMR1(t) = 0x3131u; /* CC1S = CC2S = TI, input filter 8 samples */
        TIM_CCER(t) = 0;
        TIM_SMCR(t) = 3u;       /* encoder mode 3: count both edges of both channels */
        TIM_ARR(t) = 0xFFFFFFFFu; /* 32-bit on TIM2/5, 0xFFFF on TIM3/4: the core uses 16 bits */
        TIM_CNT(t) = 0;
        TIM_CR1(t) = 1u;
    }
}

uint16_t hal_encoder_raw(unsigned wheel) { return (uint16_t)TIM_CNT(ENC_TIM[wheel]); }

/* ---- motors: TIM1 CH1..CH4 PWM on PE9, PE11, PE13, PE14; direction PE7, PE8, PE10, PE12 -------- */
static const uint8_t PWM_PIN[4] = {9, 11, 13, 14};
static const uint8_t DIR_PIN[4] = {7, 8, 10, 12};
#define PWM_TOP (APB2_HZ * 2u / PWM_HZ - 1u) /* TIM1 runs at 2 x APB2 */

static void motors_init(void) {
    for (unsigned i = 0; i < 4; i++) {
        pin_mode(PORT_E, PWM_PIN[i], MODE_AF, 1);
        pin_mode(PORT_E, DIR_PIN[i], MODE_OUT, 0);
    }
    TIM_PSC(TIM1_BASE) = 0;
    TIM_ARR(TIM1_BASE) = PWM_TOP;
    TIM_CCMR1(TIM1_BASE) = 0x6868u; /* CH1, CH2: PWM mode 1, preload */
    TIM_CCMR2(TIM1_BASE) = 0x6868u; /* CH3, CH4 */
    TIM_CCER(TIM1_BASE) = 0x1111u;
    TIM_BDTR(TIM1_BASE) = 1u << 15; /* MOE: advanced timer outputs on */
    TIM_EGR(TIM1_BASE) = 1u;
    TIM_CR1(TIM1_BASE) = (1u << 7) | 1u;
}

void hal_motor_set(unsigned wheel, float duty) {
    if (duty > 1.0f) duty = 1.0f;
    if (duty < -1.0f) duty = -1.0f;
    pin_write(PORT_E, DIR_PIN[wheel], duty >= 0.0f);
    const float mag = duty >= 0.0f ? duty : -duty;
    TIM_CCR(TIM1_BASE, wheel + 1u) = (uint32_t)(mag * (float)PWM_TOP);
}

void hal_motor_brake_all(void) {
    /* PWM low: sign-magnitude drivers (Cytron MD10C and the like) short the motor = brake */
    for (unsigned i = 0; i < 4; i++) TIM_CCR(TIM1_BASE, i + 1u) = 0;
}

/* ---- MPU6050 on I2C1 (PB6 SCL, PB7 SDA), 400 kHz, polled -------------------------------------- */
#define I2C_TIMEOUT 20000u
static int g_imu_ready;

static int i2c_wait(uint32_t sr1_bit) {
    for (uint32_t n = 0; n < I2C_TIMEOUT; n++) {
        const uint32_t sr1 = I2C1_SR1;
        if (sr1 & (1u << 10)) { /* AF: no acknowledge */
            I2C1_SR1 = ~(1u << 10);
            I2C1_CR1 |= 1u << 9;
            return 2;
        }
        if (sr1 & sr1_bit) return 0;
    }
    I2C1_CR1 |= 1u << 9;
    return 1; /* time-out: bus stuck or device gone */
}

static int i2c_start(uint8_t addr_rw) {
    I2C1_CR1 |= 1u << 8; /* START */
    if (i2c_wait(1u << 0)) return 1;
    I2C1_DR = addr_rw;
    int e = i2c_wait(1u << 1); /* ADDR */
    return e;
}

static int i2c_write_reg(uint8_t reg, uint8_t value) {
    int e = i2c_start((uint8_t)(MPU6050_ADDR << 1));
    if (e) return e;
    (void)I2C1_SR2;
    I2C1_DR = reg;
    if ((e = i2c_wait(1u << 7))) return e;
    I2C1_DR = value;
    if ((e = i2c_wait(1u << 2))) return e; /* BTF */
    I2C1_CR1 |= 1u << 9;
    return 0;
}

static int i2c_read_regs(uint8_t reg, uint8_t *out, unsigned n) {
    int e = i2c_start((uint8_t)(MPU6050_ADDR << 1));
    if (e) return e;
    (void)I2C1_SR2;
    I2C1_DR = reg;
    if ((e = i2c_wait(1u << 2))) return e;
    I2C1_CR1 |= 1u << 10; /* ACK */
    if ((e = i2c_start((uint8_t)((MPU6050_ADDR << 1) | 1u)))) return e;
    if (n == 1) I2C1_CR1 &= ~(1u << 10);
    (void)I2C1_SR2; /* clears ADDR: reception starts */
    for (unsigned i = 0; i < n; i++) {
        if (i + 1 == n) { /* NACK and STOP go out with the last byte */
            I2C1_CR1 &= ~(1u << 10);
            I2C1_CR1 |= 1u << 9;
        }
        if ((e = i2c_wait(1u << 6))) return e; /* RXNE */
        out[i] = (uint8_t)I2C1_DR;
    }
    return 0;
}

static void imu_init(void) {
    pin_mode(PORT_B, 6, MODE_AF, 4);
    pin_mode(PORT_B, 7, MODE_AF, 4);
    GPIO_OTYPER(PORT_B) |= (1u << 6) | (1u << 7); /* open drain */
    I2C1_CR1 = 0;
    I2C1_CR2 = APB1_HZ / 1000000u;
    I2C1_CCR = (1u << 15) | (APB1_HZ / (3u * 400000u)); /* fast mode 400 kHz */
    I2C1_TRISE = APB1_HZ / 1000000u * 300u / 1000u + 1u;
    I2C1_CR1 = 1u;
    g_imu_ready = i2c_write_reg(0x6B, 0x00) == 0    /* PWR_MGMT_1: wake, internal clock */
                  && i2c_write_reg(0x1A, 0x03) == 0 /* CONFIG: 44 Hz low-pass */
                  && i2c_write_reg(0x1B, 0x08) == 0 /* GYRO_CONFIG: +-500 deg/s, 65.5 LSB per deg/s */
                  && i2c_write_reg(0x1C, 0x00) == 0; /* ACCEL_CONFIG: +-2 g, 16384 LSB per g */
}

int hal_imu_read(float *gyro_z, float accel[3]) {
    uint8_t b[14];
    static uint32_t last_try_ms;
    if (!g_imu_ready) {
        if (g_ms - last_try_ms < 1000u) return 3; /* retry the bus once a second, not every 5 ms */
        last_try_ms = g_ms;
        imu_init();
        if (!g_imu_ready) return 3;
    }
    int e = i2c_read_regs(0x3B, b, sizeof b); /* ACCEL_XOUT_H .. GYRO_ZOUT_L */
    if (e) {
        g_imu_ready = 0;
        return e;
    }
    const float g = 9.80665f / 16384.0f;
    /* mounted with the chip's x forward, z up: base_link axes (REP-103) */
    accel[0] = (float)(int16_t)((b[0] << 8) | b[1]) * g;
    accel[1] = (float)(int16_t)((b[2] << 8) | b[3]) * g;
    accel[2] = (float)(int16_t)((b[4] << 8) | b[5]) * g;
    *gyro_z = (float)(int16_t)((b[12] << 8) | b[13]) * (0.0174532925f / 65.5f);
    return 0;
}

/* ---- IR inputs PC0, PC1 (NPN open collector, pulled up: low = obstacle) ------------------------ */
uint8_t hal_ir_bits(void) {
    const uint32_t idr = GPIO_IDR(PORT_C);
    return (uint8_t)((!(idr & 1u) ? 1u : 0u) | (!(idr & 2u) ? 2u : 0u));
}

/* ---- battery on PC2 / ADC1 channel 12 ---------------------------------------------------------- */
static void adc_init(void) {
    pin_mode(PORT_C, 2, MODE_ANALOG, 0);
    ADC_CCR = 1u << 16; /* ADCCLK = APB2 / 4 = 21 MHz */
    ADC1_SMPR1 = 7u << (3u * (BATTERY_ADC_CHANNEL - 10u)); /* 480 cycles: a high-impedance divider */
    ADC1_SQR3 = BATTERY_ADC_CHANNEL;
    ADC1_CR2 = 1u; /* ADON */
}

uint16_t hal_battery_mv(void) {
    ADC1_CR2 |= 1u << 30; /* SWSTART */
    for (uint32_t n = 0; n < 10000u && !(ADC1_SR & 2u); n++) {
    }
    const float mv = (float)(ADC1_DR & 0xFFFu) * (3300.0f / 4095.0f) * BATTERY_DIVIDER;
    return (uint16_t)(mv > 65535.0f ? 65535.0f : mv);
}

/* ---- parameter flash sector -------------------------------------------------------------------- */
int hal_flash_read(void *buf, size_t n) {
    memcpy(buf, (const void *)(uintptr_t)PARAM_FLASH_ADDR, n);
    return 0; /* an erased sector reads 0xFF: the core's magic + CRC check rejects it */
}

static int flash_wait(void) {
    for (uint32_t n = 0; n < 50000000u; n++)
        if (!(FLASH_SR & (1u << 16))) return (FLASH_SR & 0xF2u) ? -1 : 0; /* BSY clear; error bits */
    return -1;
}

int hal_flash_write(const void *buf, size_t n) {
    if (FLASH_CR & (1u << 31)) { /* LOCK */
        FLASH_KEYR = 0x45670123u;
        FLASH_KEYR = 0xCDEF89ABu;
    }
    FLASH_SR = 0xF3u; /* clear old error flags */
    int err = flash_wait();
    if (!err) {
        FLASH_CR = (1u << 1) | (PARAM_FLASH_SNB << 3) | (2u << 8); /* SER, sector, x32 */
        FLASH_CR |= 1u << 16;                                     /* STRT */
        err = flash_wait();
    }
    const uint8_t *src = buf;
    for (size_t i = 0; !err && i < n; i += 4) {
        uint32_t word = 0xFFFFFFFFu;
        memcpy(&word, src + i, n - i < 4 ? n - i : 4);
        FLASH_CR = 1u | (2u << 8); /* PG, x32 */
        REG(PARAM_FLASH_ADDR + i) = word;
        err = flash_wait();
    }
    FLASH_CR = 1u << 31; /* lock again */
    return err;
}

void hal_reboot(void) {
    SCB_AIRCR = 0x05FA0004u; /* VECTKEY | SYSRESETREQ */
    for (;;) {
    }
}

/* ---- board bring-up ---------------------------------------------------------------------------- */
void board_init(void) {
    clock_init();
    RCC_AHB1ENR |= 0x1Fu | (1u << 22);                            /* GPIOA..E, DMA2 */
    RCC_APB1ENR |= (1u << 0) | (1u << 1) | (1u << 2) | (1u << 3) | (1u << 21); /* TIM2..5, I2C1 */
    RCC_APB2ENR |= (1u << 0) | (1u << 4) | (1u << 8);             /* TIM1, USART1, ADC1 */
    pin_mode(PORT_C, 0, MODE_IN, 0);
    pin_mode(PORT_C, 1, MODE_IN, 0);
    pin_pull_up(PORT_C, 0);
    pin_pull_up(PORT_C, 1);
    uart_init();
    encoders_init();
    motors_init();
    adc_init();
    imu_init();
}

void board_poll(void) { tx_kick(); }

uint32_t board_ms(void) { return g_ms; }
