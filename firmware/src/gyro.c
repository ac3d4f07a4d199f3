/* Gyro: see gyro.h. Register map and scales: InvenSense MPU-6000/MPU-6050 Register Map and
 * Descriptions (RM-MPU-6000A-00 rev 4.2): PWR_MGMT_1 0x6B, CONFIG 0x1A, GYRO_CONFIG 0x1B,
 * GYRO_ZOUT_H 0x47 (big-endian, then _L), WHO_AM_I 0x75 (0x68 on the MPU-6050). */
#include "config.h"
#include "gyro.h"
#include "twi.h"

#define GYRO_ADDR        0x68u     /* AD0 low */
#define REG_CONFIG       0x1Au
#define REG_GYRO_CONFIG  0x1Bu
#define REG_GYRO_ZOUT_H  0x47u
#define REG_PWR_MGMT_1   0x6Bu
#define REG_WHO_AM_I     0x75u
#define WHO_AM_I_6050    0x68u

/* configuration writes after a successful probe, in order */
static const uint8_t setup[][2] = {
    {REG_PWR_MGMT_1, 0x01},                    /* wake from sleep, clock from the X gyro PLL (datasheet's advice) */
    {REG_CONFIG, 0x03},                        /* DLPF_CFG 3: gyro bandwidth 42 Hz, below the 100 Hz Nyquist of 200 Hz sampling */
    {REG_GYRO_CONFIG, GYRO_FS_SEL << 3},       /* full scale, config.h */
};
#define N_SETUP (sizeof setup / sizeof setup[0])

enum { PROBE, SETUP0, RUN = SETUP0 + N_SETUP, FAILED };

static uint8_t step = PROBE;
static uint8_t pending;                 /* a transaction of ours is on the bus */
static uint8_t tx[2], rx[2];
static uint16_t started_ms, next_ms, window_ms;
static int32_t sum;                     /* samples in the current window */
static uint8_t n;
static int16_t rate;
static uint8_t ok;

void gyro_init(void)
{
    twi_init();
}

static void fail(uint16_t now_ms)
{
    step = FAILED;
    ok = 0;
    rate = 0;
    next_ms = (uint16_t)(now_ms + GYRO_RETRY_MS);
}

static void begin(uint16_t now_ms)
{
    if (step == PROBE) {
        tx[0] = REG_WHO_AM_I;
        pending = twi_start(GYRO_ADDR, tx, 1, rx, 1);
    } else if (step < RUN) {
        tx[0] = setup[step - SETUP0][0];
        tx[1] = setup[step - SETUP0][1];
        pending = twi_start(GYRO_ADDR, tx, 2, 0, 0);
    } else {
        tx[0] = REG_GYRO_ZOUT_H;
        pending = twi_start(GYRO_ADDR, tx, 1, rx, 2);
        next_ms = (uint16_t)(now_ms + GYRO_PERIOD_MS);
    }
    started_ms = now_ms;
}

static void finished(uint16_t now_ms)
{
    if (step == PROBE) {
        if (rx[0] != WHO_AM_I_6050)
            return fail(now_ms);
        step = SETUP0;
    } else if (step < RUN) {
        if (++step == RUN) {
            window_ms = now_ms;
            sum = 0;
            n = 0;
        }
    } else {
        sum += (int16_t)((uint16_t)rx[0] << 8 | rx[1]);     /* GYRO_ZOUT_H first */
        n++;
    }
}

void gyro_tick(uint16_t now_ms)
{
    if (pending) {
        enum twi_status s = twi_status();
        if (s == TWI_BUSY) {
            if ((uint16_t)(now_ms - started_ms) < GYRO_BUS_TIMEOUT_MS)
                return;
            twi_reset();                                    /* a hung bus */
            s = TWI_ERROR;
        }
        pending = 0;
        if (s == TWI_DONE)
            finished(now_ms);
        else
            fail(now_ms);
    }
    if (step == RUN && (uint16_t)(now_ms - window_ms) >= ENC_WINDOW_MS) {
        window_ms += ENC_WINDOW_MS;
        if (n) {                                            /* rounded mean of the window */
            rate = (int16_t)((sum + (sum >= 0 ? n / 2 : -(int32_t)(n / 2))) / n);
            ok = 1;
        }
        sum = 0;
        n = 0;
    }
    if (!pending && (int16_t)(now_ms - next_ms) >= 0) {
        if (step == FAILED)
            step = PROBE;
        begin(now_ms);
    }
}

uint8_t gyro_ok(void)
{
    return ok;
}

int16_t gyro_rate(void)
{
    return rate;
}
