/* Reference base firmware for the STM32F429: the portable core on the register-level board layer.
 * A bare-metal super-loop on the 1 ms SysTick: each tick drains the UART DMA ring into the frame
 * decoder and runs whichever core jobs are due (control 10 ms, IMU 5 ms, telemetry 1/rate). */
#include "board.h"
#include "nd_core.h"

void board_init(void);
void board_poll(void);
uint32_t board_ms(void);

static nd_core_t g_core;

int main(void) {
    board_init();
    const nd_board_t board = {ROBOT_KINEMATICS, ROBOT_WHEELS, ROBOT_WHEEL_MAX_RAD_S};
    const nd_geometry_t geometry = {ROBOT_WHEEL_RADIUS, ROBOT_TRACK_WIDTH,   ROBOT_WHEEL_BASE,
                                    ROBOT_TICKS_PER_REV, ROBOT_OMNI_RADIUS, ROBOT_BATTERY_CUTOFF};
    nd_core_init(&g_core, &board, &geometry);
    uint32_t last = board_ms();
    for (;;) {
        while (board_ms() == last) __asm__ volatile("wfi"); /* sleep until the next tick */
        last = board_ms();
        nd_core_step(&g_core);
        board_poll();
    }
}
