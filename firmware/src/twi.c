/* TWI master: see twi.h. Status codes: ATmega2560 datasheet, TWI master transmitter/receiver
 * tables (util/twi.h names). */
#include "config.h"
#include "twi.h"

#include <avr/interrupt.h>
#include <avr/io.h>
#include <util/twi.h>

#define TWCR_GO (_BV(TWINT) | _BV(TWEN) | _BV(TWIE))

static volatile enum twi_status status;
static uint8_t sla;                 /* 7-bit address << 1 */
static const uint8_t *wbuf;
static uint8_t *rbuf;
static uint8_t wlen, rlen, idx;
static volatile uint8_t reading;

void twi_init(void)
{
    /* SCL = F_CPU / (16 + 2 * TWBR * prescaler): 16 MHz, TWBR 12, prescaler 1 -> 400 kHz */
    TWSR = 0;
    TWBR = (uint8_t)((F_CPU / TWI_HZ - 16UL) / 2UL);
    TWCR = _BV(TWEN);
    status = TWI_IDLE;
}

void twi_reset(void)
{
    TWCR = 0;
    twi_init();
}

enum twi_status twi_status(void)
{
    return status;
}

uint8_t twi_start(uint8_t addr7, const uint8_t *w, uint8_t wl, uint8_t *r, uint8_t rl)
{
    if (status == TWI_BUSY || (TWCR & _BV(TWSTO)))      /* running, or the last STOP not yet sent */
        return 0;
    sla = (uint8_t)(addr7 << 1);
    wbuf = w;
    wlen = wl;
    rbuf = r;
    rlen = rl;
    idx = 0;
    reading = wl == 0;
    status = TWI_BUSY;
    TWCR = TWCR_GO | _BV(TWSTA);
    return 1;
}

static void finish(enum twi_status s)
{
    TWCR = _BV(TWINT) | _BV(TWEN) | _BV(TWSTO);
    status = s;
}

ISR(TWI_vect)
{
    switch (TW_STATUS) {
    case TW_START:
    case TW_REP_START:
        TWDR = (uint8_t)(sla | (reading ? TW_READ : TW_WRITE));
        TWCR = TWCR_GO;
        break;
    case TW_MT_SLA_ACK:
    case TW_MT_DATA_ACK:            /* (simavr 1.6 reports this one after SLA+W too) */
        if (idx < wlen) {
            TWDR = wbuf[idx++];
            TWCR = TWCR_GO;
        } else if (rlen) {
            reading = 1;
            idx = 0;
            TWCR = TWCR_GO | _BV(TWSTA);                /* repeated start, then SLA+R */
        } else {
            finish(TWI_DONE);
        }
        break;
    case TW_MR_SLA_ACK:
        TWCR = TWCR_GO | (rlen > 1 ? _BV(TWEA) : 0);    /* ACK every byte but the last */
        break;
    case TW_MR_DATA_ACK:
        rbuf[idx++] = TWDR;
        TWCR = TWCR_GO | (idx + 1 < rlen ? _BV(TWEA) : 0);
        break;
    case TW_MR_DATA_NACK:
        rbuf[idx++] = TWDR;
        finish(TWI_DONE);
        break;
    default:                        /* NACK on address or data, arbitration lost, bus error */
        finish(TWI_ERROR);
        break;
    }
}
