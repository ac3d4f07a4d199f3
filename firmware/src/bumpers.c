/* Bumpers: see bumpers.h. */
#include "bumpers.h"
#include "config.h"

#include <avr/io.h>

#define BUMPER_MASK 0x0Fu

static uint8_t stable, candidate, same_ms, pressed_since;

void bumpers_init(void)
{
    DDRC &= (uint8_t)~BUMPER_MASK;
    PORTC |= BUMPER_MASK;                           /* pull-ups */
}

void bumpers_tick(void)
{
    uint8_t raw = (uint8_t)(~PINC & BUMPER_MASK);   /* low = pressed */
    if (raw != candidate) {
        candidate = raw;
        same_ms = 0;
    } else if (raw != stable && ++same_ms >= BUMPER_DEBOUNCE_MS) {
        stable = raw;                               /* unchanged for the debounce time */
    }
    pressed_since |= stable;
}

uint8_t bumpers_now(void)
{
    return stable;
}

uint8_t bumpers_take_pressed(void)
{
    uint8_t p = pressed_since;
    pressed_since = stable;
    return p;
}
