/* Infrared range sensors: see ranges.h.
 *
 * Sampling: every RANGE_SAMPLE_MS the tick starts a sweep; each conversion's interrupt reads
 * its channel, selects the next and starts it (single conversions chained by the ISR, so the
 * result always belongs to the channel selected before it started, on the chip as in simavr;
 * a free-running ADC would convert the old channel once more after every switch). 16 MHz /128
 * = 125 kHz ADC clock (within the 50-200 kHz of full 10-bit resolution, ATmega2560 data sheet),
 * 13 ADC clocks = 104 us per conversion, 0.94 ms per sweep of nine. AVcc reference: on the
 * robot the Mega's 5 V comes from its on-board regulator, and the sensors run from it too.
 *
 * Averaging: the GP2Y0A21YK0F updates its output once per 38.3 +- 9.6 ms measurement (data
 * sheet, timing chart); the mean of all samples in a RANGE_WINDOW_MS window (25 per sensor)
 * spans about one measurement and averages the output's noise (dithering below one ADC step).
 *
 * Voltage -> distance: Sharp GP2Y0A21YK0F data sheet
 * (https://global.sharp/products/device/lineup/data/pdf/datasheet/gp2y0a21yk_e.pdf),
 * typical values, white paper (90 % reflectance): the electro-optical table gives
 * Vo = 0.4 V at L = 80 cm and dVo = 1.9 V from 80 cm to 10 cm (so 2.3 V at 10 cm); the
 * points between are read off its output-vs-distance figure on page 5 (as also tabulated in
 * O. Kamppari's GP2Y0A21.cpp driver, 2017). Between points the output is close to linear in
 * 1/distance (the data sheet's second figure plots it against 1/(L + 0.42 cm)), so the
 * table is interpolated piecewise-linearly in 1/distance.
 * Above the 10 cm voltage: the output peaks above 3 V at 6-8 cm and folds back below
 * that; on the robot that zone lies inside the bumper ring (robot.ranging.RangeLayout), so a
 * reading above the 10 cm point is clamped to 10 cm. Below the 80 cm voltage: no return. */
#include "config.h"
#include "protocol.h"
#include "ranges.h"

#include <avr/interrupt.h>
#include <avr/io.h>

#if RANGE_SENSORS > RANGE_SLOTS
#error "RANGE_SENSORS: at most RANGE_SLOTS sensors (ADC0..ADC8)"
#endif

static uint8_t cm[RANGE_SLOTS];

#if RANGE_SENSORS
#define OVERSAMPLE  8u      /* window means are kept in 1/8 ADC counts */
/* mV -> 1/8 ADC counts at the 5.000 V AVcc reference: ADC = Vin * 1024 / Vref (ATmega2560 data sheet) */
#define Q(mv)       ((uint16_t)(((uint32_t)(mv) * 1024u * OVERSAMPLE + 2500u) / 5000u))
#define INV(d)      ((uint16_t)((65536ul + (d) / 2) / (d)))         /* 2^16 / d (cm) */

static const struct {
    uint16_t q;             /* typical output (1/8 ADC counts), falling with distance */
    uint16_t inv;           /* 2^16 / distance (cm) */
} knots[] = {
    {Q(2300), INV(10)}, {Q(1300), INV(20)}, {Q(900), INV(30)}, {Q(750), INV(40)},
    {Q(600), INV(50)},  {Q(500), INV(60)},  {Q(450), INV(70)}, {Q(400), INV(80)},
};
#define N_KNOTS (sizeof knots / sizeof knots[0])

/* A sweep in progress belongs to the ISR (ch, sum, sweeps); the tick touches them only while
 * no sweep runs, so neither side needs to block interrupts (the barriers keep the compiler
 * from moving those accesses across the hand-over). */
#define BARRIER() __asm__ __volatile__("" ::: "memory")
static volatile uint8_t busy;
static uint8_t ch;
static uint16_t sum[RANGE_SENSORS];     /* <= 64 sweeps of 1023 fit */
static uint8_t sweeps;

static uint16_t window_ms, sample_ms;
static uint16_t done_sum[RANGE_SENSORS];
static uint8_t done_sweeps;
static uint8_t conv = RANGE_SENSORS;    /* next sensor to convert; RANGE_SENSORS: none pending */
static uint8_t skip = (RANGE_WARMUP_MS + RANGE_WINDOW_MS - 1) / RANGE_WINDOW_MS;
static uint8_t ok;

/* ADC0..7 are MUX4:0 = channel with MUX5 = 0, ADC8..15 the same with MUX5 = 1 (ATmega2560 data sheet, table 26-4). */
static inline void select(uint8_t c)
{
    ADCSRB = c >= 8u ? _BV(MUX5) : 0u;
    ADMUX = _BV(REFS0) | (c & 7u);
}

ISR(ADC_vect)
{
    sum[ch] += ADC;
    if (++ch < RANGE_SENSORS) {
        select(ch);
        ADCSRA |= _BV(ADSC);
    } else {
        sweeps++;
        busy = 0;
    }
}

void ranges_init(void)
{
    /* no digital input buffers on the analog pins */
    DIDR0 = (uint8_t)(RANGE_SENSORS >= 8u ? 0xFFu : (1u << RANGE_SENSORS) - 1u);
    DIDR2 = (uint8_t)(RANGE_SENSORS > 8u ? (1u << (RANGE_SENSORS - 8u)) - 1u : 0u);
    select(0);                                          /* AVcc reference, ADC0 */
    ADCSRA = _BV(ADEN) | _BV(ADIE) | _BV(ADPS2) | _BV(ADPS1) | _BV(ADPS0);   /* /128: 125 kHz */
}

/* Mean reading (1/8 ADC counts) -> cm, RANGE_MIN_CM..RANGE_MAX_CM or RANGE_NO_RETURN. */
static uint8_t to_cm(uint16_t q)
{
    if (q >= knots[0].q)
        return RANGE_MIN_CM;
    if (q < knots[N_KNOTS - 1].q)
        return RANGE_NO_RETURN;
    uint8_t i = 0;
    while (q < knots[i + 1].q)
        i++;                                            /* knots[i].q > q >= knots[i + 1].q */
    uint16_t dq = knots[i].q - knots[i + 1].q;
    uint16_t di = knots[i].inv - knots[i + 1].inv;
    uint16_t inv = knots[i + 1].inv + (uint16_t)(((uint32_t)(q - knots[i + 1].q) * di + dq / 2) / dq);
    return (uint8_t)((65536ul + inv / 2) / inv);
}

void ranges_tick(uint16_t now_ms)
{
    if (conv < RANGE_SENSORS) {                         /* one division pair per tick, not nine at once */
        cm[conv] = done_sweeps ? to_cm((uint16_t)(((uint32_t)done_sum[conv] * OVERSAMPLE + done_sweeps / 2)
                                                  / done_sweeps))
                               : RANGE_NO_RETURN;
        if (++conv == RANGE_SENSORS)
            ok = done_sweeps != 0;
    }
    if (busy)
        return;                                         /* ticks caught up late: the sweep still runs */
    BARRIER();
    if ((uint16_t)(now_ms - window_ms) >= RANGE_WINDOW_MS) {
        window_ms += RANGE_WINDOW_MS;
        if (skip) {
            skip--;                                     /* the sensors' first output is not ready yet */
        } else {
            for (uint8_t i = 0; i < RANGE_SENSORS; i++)
                done_sum[i] = sum[i];
            done_sweeps = sweeps;
            conv = 0;
        }
        for (uint8_t i = 0; i < RANGE_SENSORS; i++)
            sum[i] = 0;
        sweeps = 0;
    }
    if ((uint16_t)(now_ms - sample_ms) >= RANGE_SAMPLE_MS) {
        sample_ms = now_ms;
        ch = 0;
        busy = 1;
        BARRIER();
        select(0);
        ADCSRA |= _BV(ADSC);
    }
}

uint8_t ranges_ok(void)
{
    return ok;
}
#else
void ranges_init(void) {}
void ranges_tick(uint16_t now_ms) { (void)now_ms; }
uint8_t ranges_ok(void) { return 0; }
#endif

uint8_t ranges_cm(uint8_t i)
{
    return ranges_ok() && i < RANGE_SLOTS ? cm[i] : RANGE_NO_RETURN;
}
