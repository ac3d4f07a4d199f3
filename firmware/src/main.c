/* Omni-drive controller for the ATmega2560 (16 MHz): receives body twists or headings
 * from the host over UART0 (docs/protocol.md), drives three omni wheels through
 * H-bridges (PWM + direction) and reports wheel encoders and faults.
 *
 * Also reads an MPU-6050-class I2C gyro (yaw rate), up to four bumper switches and up to
 * eight analog infrared range sensors (ADC).
 *
 * Timers: T0 1 kHz tick, T1 free-running cycle counter (profiling), T4 motor PWM. */
#include "bumpers.h"
#include "config.h"
#include "drive.h"
#include "gyro.h"
#include "link.h"
#include "protocol.h"
#include "ranges.h"

#include <avr/interrupt.h>
#include <avr/io.h>
#include <avr/sleep.h>
#include <avr/wdt.h>
#include <math.h>
#include <string.h>
#include <util/atomic.h>

volatile uint16_t g_ms;                 /* 1 kHz tick (wraps every 65.5 s; use differences) */
static volatile uint32_t uptime_ms;
static uint16_t latched_faults;         /* WDT_RESET, BROWNOUT_RESET, RX_OVERFLOW */
static uint16_t max_parse_cycles, max_cmd_cycles;   /* T1 cycles, incl. interrupts taken meanwhile */

/* The reset cause, saved before the watchdog is disabled: after a watchdog reset the WDT
 * stays enabled with the shortest timeout, so it must be turned off before C init runs. */
uint8_t mcusr_at_reset __attribute__((section(".noinit")));
void early_wdt_off(void) __attribute__((naked, used, section(".init3")));
void early_wdt_off(void)
{
    mcusr_at_reset = MCUSR;
    MCUSR = 0;
    wdt_disable();
}

ISR(TIMER0_COMPA_vect)
{
    g_ms++;
    uptime_ms++;
}

static void put_u16(uint8_t *p, uint16_t v) { p[0] = (uint8_t)v; p[1] = (uint8_t)(v >> 8); }
static void put_u32(uint8_t *p, uint32_t v) { put_u16(p, (uint16_t)v); put_u16(p + 2, (uint16_t)(v >> 16)); }
static int16_t get_i16(const uint8_t *p) { return (int16_t)((uint16_t)p[0] | ((uint16_t)p[1] << 8)); }
static uint16_t get_u16(const uint8_t *p) { return (uint16_t)p[0] | ((uint16_t)p[1] << 8); }

/* Timer1 cycle counter (profiling). simavr recomputes TCNT1H on its own read instead of
 * latching it with TCNT1L, so a read straddling a low-byte wrap would be 256 off there;
 * skipping the last 8 counts before the wrap costs <= ~12 cycles of jitter on either. */
static inline uint16_t cycles_now(void)
{
    uint16_t v;
    do {
        v = TCNT1;
    } while ((uint8_t)v >= 0xF8);
    return v;
}

static uint32_t uptime(void)
{
    uint32_t t;
    ATOMIC_BLOCK(ATOMIC_RESTORESTATE) { t = uptime_ms; }
    return t;
}

static void ack(const frame_t *f, uint8_t flags)
{
    uint8_t p[2] = {f->type, flags};
    link_send(MSG_ACK, f->seq, p, 2);
}

static void nak(const frame_t *f, uint8_t reason)
{
    uint8_t p[2] = {f->type, reason};
    link_stats.naks++;
    link_send(MSG_NAK, f->seq, p, 2);
}

static void send_telemetry(uint8_t seq)
{
    uint8_t p[TELEMETRY_LEN];
    int32_t c[3];
    int16_t r[3], d[3];
    link_stats_t s;
    drive_encoders(c);
    drive_encoder_rate(r);
    drive_duty(d);
    ATOMIC_BLOCK(ATOMIC_RESTORESTATE) { s = link_stats; }
    put_u32(p, uptime());
    for (uint8_t i = 0; i < 3; i++) {
        put_u32(p + 4 + 4 * i, (uint32_t)c[i]);
        put_u16(p + 16 + 2 * i, (uint16_t)r[i]);
        put_u16(p + 22 + 2 * i, (uint16_t)d[i]);
    }
    put_u16(p + 28, (uint16_t)(drive_faults() | latched_faults));
    const uint16_t counters[10] = {s.rx_frames, s.crc_errors, s.length_errors, s.timeouts,
                                   s.dropped_bytes, s.naks, s.rx_overflows, s.tx_dropped,
                                   max_parse_cycles, max_cmd_cycles};
    for (uint8_t i = 0; i < 10; i++)
        put_u16(p + 30 + 2 * i, counters[i]);
    put_u16(p + 50, (uint16_t)gyro_rate());
    p[52] = (uint8_t)((gyro_ok() ? SENSOR_GYRO_OK : 0) | (ranges_ok() ? SENSOR_RANGES_OK : 0));
    p[53] = (uint8_t)(bumpers_now() | (uint8_t)(bumpers_take_pressed() << 4));
    for (uint8_t i = 0; i < RANGE_SLOTS; i++)
        p[54 + i] = ranges_cm(i);
    link_send(MSG_TELEMETRY, seq, p, TELEMETRY_LEN);
}

static uint16_t ms_now(void)
{
    uint16_t t;
    ATOMIC_BLOCK(ATOMIC_RESTORESTATE) { t = g_ms; }
    return t;
}

static void dispatch(const frame_t *f)
{
    switch (f->type) {
    case MSG_PING: {
        if (f->len != 4)
            return nak(f, NAK_BAD_LENGTH);
        uint8_t p[PONG_LEN];
        memcpy(p, f->payload, 4);
        p[4] = PROTO_VERSION;
        put_u16(p + 5, FW_VERSION);
        put_u32(p + 7, uptime());
        put_u16(p + 11, PWM_TOP);
        p[13] = RANGE_SENSORS;
        link_send(MSG_PONG, f->seq, p, PONG_LEN);
        return;
    }
    case MSG_SET_TWIST: {
        if (f->len != 6)
            return nak(f, NAK_BAD_LENGTH);
        float vx = get_i16(f->payload) * 1e-3f;
        float vy = get_i16(f->payload + 2) * 1e-3f;
        float om = get_i16(f->payload + 4) * 1e-3f;
        return ack(f, drive_set_twist(vx, vy, om, ms_now()) ? ACK_SPEED_LIMITED : 0);
    }
    case MSG_SET_HEADING: {
        if (f->len != 6)
            return nak(f, NAK_BAD_LENGTH);
        int16_t az_mrad = get_i16(f->payload);
        if (az_mrad > AZIMUTH_LIMIT_MRAD || az_mrad < -AZIMUTH_LIMIT_MRAD)
            return nak(f, NAK_BAD_VALUE);
        float az = az_mrad * 1e-3f;
        float speed = get_u16(f->payload + 2) * 1e-3f;
        float om = get_i16(f->payload + 4) * 1e-3f;
        return ack(f, drive_set_twist(speed * cosf(az), speed * sinf(az), om, ms_now()) ? ACK_SPEED_LIMITED : 0);
    }
    case MSG_STOP:
        if (f->len != 0)
            return nak(f, NAK_BAD_LENGTH);
        drive_stop();
        return ack(f, 0);
    case MSG_GET_TELEMETRY:
        if (f->len != 0)
            return nak(f, NAK_BAD_LENGTH);
        return send_telemetry(f->seq);
    case MSG_CLEAR_FAULTS: {
        if (f->len != 2)
            return nak(f, NAK_BAD_LENGTH);
        uint16_t mask = get_u16(f->payload);
        latched_faults &= (uint16_t)~mask;
        drive_clear_faults(mask);
        return ack(f, 0);
    }
    default:
        return nak(f, NAK_UNKNOWN_TYPE);
    }
}

int main(void)
{
    if (mcusr_at_reset & _BV(WDRF))
        latched_faults |= FAULT_WDT_RESET;
    if (mcusr_at_reset & _BV(BORF))
        latched_faults |= FAULT_BROWNOUT_RESET;

    drive_init();                                   /* outputs at zero duty first */
    link_init();
    bumpers_init();
    gyro_init();
    ranges_init();
    /* T0: CTC, /64, OCR0A 249 -> 1 kHz */
    TCCR0A = _BV(WGM01);
    TCCR0B = _BV(CS01) | _BV(CS00);
    OCR0A = 249;
    TIMSK0 = _BV(OCIE0A);
    /* T1: free-running at F_CPU, read around the parser and command execution */
    TCCR1A = 0;
    TCCR1B = _BV(CS10);

    wdt_enable(WDTO_120MS);
    set_sleep_mode(SLEEP_MODE_IDLE);
    sei();

    uint16_t done_ms = 0;
    frame_t f;
    for (;;) {
        wdt_reset();
        uint16_t now = ms_now();
        while (done_ms != now) {
            drive_tick(++done_ms);
            bumpers_tick();
            gyro_tick(done_ms);
            ranges_tick(done_ms);
        }
        if (link_rx_overflowed())
            latched_faults |= FAULT_RX_OVERFLOW;

        /* parse everything received; each parser call (one frame at most, rescans included)
         * and each command execution is timed with Timer1 */
        link_rx_mark_seen();              /* bytes arriving from here on keep us awake */
        for (;;) {
            uint16_t t0 = cycles_now();
            uint8_t got = link_poll(&f);
            uint16_t dt = (uint16_t)(cycles_now() - t0);
            if (dt > max_parse_cycles)
                max_parse_cycles = dt;
            if (!got)
                break;
            t0 = cycles_now();
            dispatch(&f);
            dt = (uint16_t)(cycles_now() - t0);
            if (dt > max_cmd_cycles)
                max_cmd_cycles = dt;
        }

        /* sleep until there is work (a received byte or a tick); an interrupt that brings
         * neither (ADC conversions, encoder edges, I2C, transmit) sleeps again at once
         * instead of running the loop; sei; sleep is atomic */
        cli();
        while (!link_rx_new() && g_ms == done_ms) {
            sleep_enable();
            sei();
            sleep_cpu();
            sleep_disable();
            cli();
        }
        sei();
    }
}
