/* QEMU's MPS2 board with the AN500 image (Cortex-M7, double-precision FPU): the registers
 * the programs for it use, and what they share (mps2_start.c): the startup (vector
 * table, .data/.bss, the FPU) and a polled writer on UART0.  Memory map: code in the
 * 4 MB SSRAM1 at 0x00000000, data in SSRAM2/3 at 0x20000000 (mps2.ld). */
#ifndef SERVO_FW_MPS2_H
#define SERVO_FW_MPS2_H

#include <stdint.h>

#define REG(a) (*(volatile uint32_t *)(a))
#define UART0 0x40004000u /* CMSDK APB UART */
#define UART_DATA REG(UART0 + 0x00)
#define UART_STATE REG(UART0 + 0x04) /* bit 0 TX full, bit 1 RX full */
#define UART_CTRL REG(UART0 + 0x08)  /* bit 0 TX enable, bit 1 RX enable */
#define UART_BAUDDIV REG(UART0 + 0x10)
#define TIMER0 0x40000000u /* CMSDK APB timer, counts down at PCLK */
#define TIMER_CTRL REG(TIMER0 + 0x00)
#define TIMER_VALUE REG(TIMER0 + 0x04)
#define TIMER_RELOAD REG(TIMER0 + 0x08)
#define PCLK_MHZ 25u
#define CPACR REG(0xE000ED88u)
#define INSN_PER_COUNT 40u /* under QEMU -icount shift=0: 1 ns per instruction, 40 ns per 25 MHz count */

/* The program's entry, called by the reset handler once memory and the FPU are set up. */
int main(void);

/* What a fault handler does before it hangs (the firmware: zero current); each program
 * defines it. */
void mps2_fault(void);

/* Write a NUL-terminated string / an unsigned decimal to UART0, waiting while it is full. */
void mps2_put(const char *s);
void mps2_put_u32(uint32_t v);

#endif
