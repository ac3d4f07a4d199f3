/* Interrupt-driven TWI (I2C) master on SCL PD0 / SDA PD1 (Mega D21 / D20), 400 kHz.
 * One transaction at a time: write some bytes, then (repeated start) read some; the main
 * loop polls twi_status() and never waits for the bus. */
#ifndef TWI_H
#define TWI_H

#include <stdint.h>

enum twi_status { TWI_IDLE, TWI_BUSY, TWI_DONE, TWI_ERROR };

void twi_init(void);
/* Start: write wlen bytes of w to the 7-bit address, then read rlen bytes into r (r must
 * stay valid until done). Returns 0 if a transaction is still running. */
uint8_t twi_start(uint8_t addr7, const uint8_t *w, uint8_t wlen, uint8_t *r, uint8_t rlen);
enum twi_status twi_status(void);   /* DONE / ERROR stay until the next twi_start */
void twi_reset(void);               /* abandon a hung transaction: release the bus, re-init */

#endif
