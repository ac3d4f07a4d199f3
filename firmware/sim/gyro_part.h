/* A virtual MPU-6050 gyro on simavr's TWI bus (7-bit address 0x68), for the simdrive harness.
 *
 * Register file as the MPU-6050 Register Map (RM-MPU-6000A-00): WHO_AM_I (0x75) reads 0x68,
 * PWR_MGMT_1 (0x6B) resets to 0x40 (sleep), the register pointer auto-increments on reads
 * and writes. GYRO_ZOUT_H/L (0x47/0x48) hold the true rate set by gyro_part_set_rate() in
 * the counts of the full scale the firmware chose in GYRO_CONFIG (0x1B, FS_SEL: 131, 65.5,
 * 32.8 or 16.4 LSB per deg/s), saturated to int16; they read 0 while the chip sleeps.
 * Bus protocol (simavr 1.6 avr_twi): the master's START message carries the 8-bit address
 * byte; we ACK it, ACK every written byte and answer every READ message with a READ carrying
 * the next register. Ideas from simavr's examples/parts/i2c_eeprom.c; no code copied. */
#ifndef GYRO_PART_H
#define GYRO_PART_H

#include <math.h>
#include <stdint.h>
#include <string.h>

#include "avr_twi.h"
#include "sim_avr.h"
#include "sim_irq.h"

#define GYRO_PART_ADDR 0x68

static struct {
    avr_irq_t *irq;          /* [TWI_IRQ_INPUT]: to the master, [TWI_IRQ_OUTPUT]: from it */
    uint8_t reg[128];
    uint8_t ptr;             /* register pointer */
    int selected;            /* addressed since the last START/STOP */
    int wrote_ptr;           /* first written byte of a write transfer (the pointer) seen */
    double rate;             /* true Z rate, rad/s */
    int unplugged;           /* answers nothing (NACK) */
} gyro_part;

static void gyro_part_set_rate(double rad_s) { gyro_part.rate = rad_s; }

/* Unplug (1) or plug in (0) the chip; plugging in powers it up afresh (registers reset). */
static void gyro_part_unplug(int unplugged)
{
    if (gyro_part.unplugged && !unplugged) {
        memset(gyro_part.reg, 0, sizeof gyro_part.reg);
        gyro_part.reg[0x75] = 0x68;
        gyro_part.reg[0x6B] = 0x40;
    }
    gyro_part.unplugged = unplugged;
}

static void gyro_part_latch_z(void)
{
    static const double lsb_per_dps[4] = {131.0, 65.5, 32.8, 16.4};
    double counts = gyro_part.rate * 180.0 / M_PI * lsb_per_dps[(gyro_part.reg[0x1B] >> 3) & 3];
    long c = lround(counts);
    if (gyro_part.reg[0x6B] & 0x40)
        c = 0;
    c = c > 32767 ? 32767 : c < -32768 ? -32768 : c;
    gyro_part.reg[0x47] = (uint8_t)((uint16_t)c >> 8);
    gyro_part.reg[0x48] = (uint8_t)c;
}

static void gyro_part_bus(struct avr_irq_t *irq, uint32_t value, void *param)
{
    (void)irq; (void)param;
    avr_twi_msg_irq_t m;
    m.u.v = value;
    if (m.u.twi.msg & TWI_COND_STOP)
        gyro_part.selected = 0;
    if (m.u.twi.msg & TWI_COND_START) {
        gyro_part.selected = (m.u.twi.addr >> 1) == GYRO_PART_ADDR && !gyro_part.unplugged;
        gyro_part.wrote_ptr = 0;
        if (gyro_part.selected) {
            gyro_part_latch_z();         /* a real chip latches its data registers per sample */
            avr_raise_irq(gyro_part.irq + TWI_IRQ_INPUT, avr_twi_irq_msg(TWI_COND_ACK, m.u.twi.addr, 1));
        }
        return;
    }
    if (!gyro_part.selected)
        return;
    if (m.u.twi.msg & TWI_COND_WRITE) {
        avr_raise_irq(gyro_part.irq + TWI_IRQ_INPUT, avr_twi_irq_msg(TWI_COND_ACK, m.u.twi.addr, 1));
        if (!gyro_part.wrote_ptr) {
            gyro_part.ptr = m.u.twi.data & 0x7F;
            gyro_part.wrote_ptr = 1;
        } else {
            uint8_t r = gyro_part.ptr;
            if (r != 0x75 && !(r >= 0x3B && r <= 0x48))      /* WHO_AM_I and the data registers are read-only */
                gyro_part.reg[r] = m.u.twi.data;
            gyro_part.ptr = (uint8_t)((r + 1) & 0x7F);
        }
    }
    if (m.u.twi.msg & TWI_COND_READ) {
        uint8_t v = gyro_part.reg[gyro_part.ptr];
        gyro_part.ptr = (uint8_t)((gyro_part.ptr + 1) & 0x7F);
        avr_raise_irq(gyro_part.irq + TWI_IRQ_INPUT, avr_twi_irq_msg(TWI_COND_READ, m.u.twi.addr, v));
    }
}

static void gyro_part_attach(avr_t *avr, uint32_t twi_irq_base)
{
    static const char *names[2] = {[TWI_IRQ_INPUT] = "8>gyro.out", [TWI_IRQ_OUTPUT] = "32<gyro.in"};
    gyro_part.reg[0x75] = 0x68;
    gyro_part.reg[0x6B] = 0x40;
    gyro_part.irq = avr_alloc_irq(&avr->irq_pool, 0, 2, names);
    avr_irq_register_notify(gyro_part.irq + TWI_IRQ_OUTPUT, gyro_part_bus, NULL);
    avr_connect_irq(gyro_part.irq + TWI_IRQ_INPUT, avr_io_getirq(avr, twi_irq_base, TWI_IRQ_INPUT));
    avr_connect_irq(avr_io_getirq(avr, twi_irq_base, TWI_IRQ_OUTPUT), gyro_part.irq + TWI_IRQ_OUTPUT);
}

#endif
