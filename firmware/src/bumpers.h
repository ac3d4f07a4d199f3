/* Bumper switches on PC0..PC3 (Mega D37, D36, D35, D34): normally-open contacts to GND,
 * internal pull-ups, so a pressed switch reads low. Up to 4; unused inputs read released. */
#ifndef BUMPERS_H
#define BUMPERS_H

#include <stdint.h>

void bumpers_init(void);
void bumpers_tick(void);                /* every 1 ms: debounce */
uint8_t bumpers_now(void);              /* debounced: bit i = switch on PCi pressed */
uint8_t bumpers_take_pressed(void);     /* switches pressed at any time since the last call */

#endif
