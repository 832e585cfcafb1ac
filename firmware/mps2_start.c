/* The startup every MPS2 AN500 program shares (mps2.h): the vector table, the reset
 * handler (.data copied, .bss zeroed, the FPU enabled, then main), the fault handler,
 * and the polled UART writer of the bench programs. */
#include "mps2.h"

void mps2_put(const char *s)
{
    while (*s) {
        while (UART_STATE & 1u)
            ;
        UART_DATA = (uint8_t)*s++;
    }
}

void mps2_put_u32(uint32_t v)
{
    char b[11];
    int i = 10;
    b[i] = 0;
    do {
        b[--i] = (char)('0' + v % 10u);
        v /= 10u;
    } while (v);
    mps2_put(b + i);
}

extern uint32_t __data_load, __data_start, __data_end, __bss_start, __bss_end, __stack_top;

void reset_handler(void)
{
    uint32_t *src = &__data_load, *dst = &__data_start;
    while (dst < &__data_end)
        *dst++ = *src++;
    for (dst = &__bss_start; dst < &__bss_end;)
        *dst++ = 0;
    CPACR |= 0xFu << 20; /* CP10, CP11: the FPU, full access */
    __asm__ volatile("dsb\n isb");
    main();
    for (;;)
        ;
}

static void hang(void)
{
    mps2_fault();
    for (;;)
        ;
}

__attribute__((section(".vectors"), used)) static void (*const vectors[16])(void) = {
    (void (*)(void))&__stack_top, reset_handler, hang, hang, hang, hang, hang, 0, 0, 0, 0, hang, hang, 0, hang, hang,
};
