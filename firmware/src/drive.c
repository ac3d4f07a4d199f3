/* Drive: see drive.h. */
#include "config.h"
#include "drive.h"
#include "protocol.h"

#include <avr/interrupt.h>
#include <avr/io.h>
#include <math.h>
#include <util/atomic.h>

/* Pins (Arduino Mega names in firmware/README.md):
 *   PWM  : OC4A PH3 (D6), OC4B PH4 (D7), OC4C PH5 (D8)   -- wheel 0, 1, 2
 *   DIR  : PA0 (D22), PA1 (D23), PA2 (D24); high = positive wheel speed
 *   ENC  : wheel i: A = PB(2i), B = PB(2i+1)  (D53 D52 | D51 D50 | D10 D11, PCINT0..5)
 *          PORTB because simavr models pin-change interrupts only there on the 2560; the
 *          external INT0..5 pins would cost the I2C bus. */
#define DIR_MASK 0x07u

_Static_assert(CMD_TIMEOUT_MS + 1u + RAMP_MS <= STOP_DEADLINE_MS, "watchdog ramp must end by STOP_DEADLINE_MS");
#define ENC_MASK 0x3Fu

static float jac[3][3];                 /* wheel speed (rad/s) = jac . (vx, vy, omega) */
static int16_t duty[3];                 /* applied signed duty */
static uint8_t active;                  /* non-zero setpoint held: the command watchdog is armed */
static uint8_t ramping;                 /* ticks into the watchdog ramp (0: not ramping) */
static int16_t ramp_from[3];            /* duties when the ramp started */
static uint8_t limited;
static uint16_t cmd_ms;                 /* tick of the last motion command */
static uint16_t faults;

static volatile int32_t enc_count[3];
static volatile uint16_t enc_edge_ms[3];
static volatile uint8_t enc_state[3];
static volatile uint8_t enc_error;
static uint8_t enc_pins;
static int32_t enc_prev[3];
static int16_t enc_rate[3];
static uint16_t enc_window_ms;
static uint16_t stall_ref_ms[3];        /* last edge, or last time the wheel was not driven hard */

extern volatile uint16_t g_ms;

/* (A,B) -> position in the quadrature cycle 00 -> 10 -> 11 -> 01 (A leads B = counting up) */
static const uint8_t quad_pos[4] = {0, 3, 1, 2};   /* index (A << 1) | B */

static uint8_t enc_pos(uint8_t pins, uint8_t i)
{
    uint8_t ab = (uint8_t)((pins >> (2 * i)) & 3u);           /* bit0 = A, bit1 = B */
    return quad_pos[(uint8_t)(((ab & 1u) << 1) | (ab >> 1))];
}

ISR(PCINT0_vect)
{
    uint8_t pins = PINB;
    uint8_t changed = (uint8_t)(pins ^ enc_pins);
    enc_pins = pins;
    for (uint8_t i = 0; i < 3; i++) {
        if (!(changed & (uint8_t)(3u << (2 * i))))
            continue;
        uint8_t pos = enc_pos(pins, i);
        uint8_t step = (uint8_t)((pos - enc_state[i]) & 3u);
        if (step == 1)
            enc_count[i]++;
        else if (step == 3)
            enc_count[i]--;
        else if (step == 2)
            enc_error = 1;                                    /* an edge was missed */
        enc_state[i] = pos;
        enc_edge_ms[i] = g_ms;
    }
}

static void apply(void)
{
    uint8_t dir = 0;
    uint16_t mag[3];
    for (uint8_t i = 0; i < 3; i++) {
        int16_t d = duty[i];
        if (d > 0)
            dir |= (uint8_t)(1u << i);
        mag[i] = (uint16_t)(d < 0 ? -d : d);
    }
    /* all channels change together, and 16-bit OCR writes go through the shared TEMP
     * register, so no interrupt in between; direction first (~30 cycles in all) */
    ATOMIC_BLOCK(ATOMIC_RESTORESTATE) {
        PORTA = (uint8_t)((PORTA & (uint8_t)~DIR_MASK) | dir);
        OCR4A = mag[0];
        OCR4B = mag[1];
        OCR4C = mag[2];
    }
}

void drive_init(void)
{
    const float ang[3] = {WHEEL0_ANGLE_DEG, WHEEL1_ANGLE_DEG, WHEEL2_ANGLE_DEG};
    for (uint8_t i = 0; i < 3; i++) {
        float th = ang[i] * (float)(M_PI / 180.0);
        jac[i][0] = -sinf(th) / WHEEL_RADIUS_M;
        jac[i][1] = cosf(th) / WHEEL_RADIUS_M;
        jac[i][2] = BASE_RADIUS_M / WHEEL_RADIUS_M;
    }
    /* motor outputs low before the pins become outputs */
    PORTA &= (uint8_t)~DIR_MASK;
    DDRA |= DIR_MASK;
    OCR4A = OCR4B = OCR4C = 0;
    ICR4 = PWM_TOP;
    /* mode 10: phase-correct PWM, TOP = ICR4; non-inverting on A, B, C; no prescaler -> 20 kHz.
     * OCR = 0 keeps the output low all period (fast PWM would leave a 1-cycle spike). */
    TCCR4A = _BV(COM4A1) | _BV(COM4B1) | _BV(COM4C1) | _BV(WGM41);
    TCCR4B = _BV(WGM43) | _BV(CS40);
    PORTH &= (uint8_t)~(_BV(PH3) | _BV(PH4) | _BV(PH5));
    DDRH |= _BV(PH3) | _BV(PH4) | _BV(PH5);

    /* encoders: inputs with pull-ups (open-collector encoder outputs), pin-change interrupt */
    DDRB &= (uint8_t)~ENC_MASK;
    PORTB |= ENC_MASK;
    enc_pins = PINB;
    for (uint8_t i = 0; i < 3; i++)
        enc_state[i] = enc_pos(enc_pins, i);
    PCMSK0 = ENC_MASK;
    PCIFR = _BV(PCIF0);
    PCICR |= _BV(PCIE0);
}

uint8_t drive_set_twist(float vx, float vy, float omega, uint16_t now_ms)
{
    float w[3];
    float peak = 0.0f;
    for (uint8_t i = 0; i < 3; i++) {
        w[i] = jac[i][0] * vx + jac[i][1] * vy + jac[i][2] * omega;
        float a = fabsf(w[i]);
        if (a > peak)
            peak = a;
    }
    /* speed limit: one factor for all wheels keeps the direction of motion (kinematics.saturate) */
    float scale = (float)PWM_TOP / MAX_WHEEL_SPEED;
    limited = peak > MAX_WHEEL_SPEED;
    if (limited)
        scale = (float)PWM_TOP / peak;
    uint8_t any = 0;
    for (uint8_t i = 0; i < 3; i++) {
        int16_t d = (int16_t)lroundf(w[i] * scale);
        if (d > (int16_t)PWM_TOP)
            d = PWM_TOP;
        if (d < -(int16_t)PWM_TOP)
            d = -(int16_t)PWM_TOP;
        duty[i] = d;
        any |= d != 0;
    }
    apply();
    active = any;
    ramping = 0;
    cmd_ms = now_ms;
    faults &= (uint16_t)~FAULT_CMD_TIMEOUT;
    return limited;
}

void drive_stop(void)
{
    duty[0] = duty[1] = duty[2] = 0;
    apply();
    active = 0;
    ramping = 0;
    limited = 0;
    faults &= (uint16_t)~FAULT_CMD_TIMEOUT;
}

void drive_tick(uint16_t now_ms)
{
    /* command watchdog: '>' because cmd_ms is the tick the command arrived in, so the ramp
     * starts 200..201 ms after it; then a linear ramp of RAMP_MS ticks, every channel in
     * proportion, so each reaches zero at the same tick whatever its duty */
    if (active && (uint16_t)(now_ms - cmd_ms) > CMD_TIMEOUT_MS) {
        faults |= FAULT_CMD_TIMEOUT;
        for (uint8_t i = 0; i < 3; i++)
            ramp_from[i] = duty[i];
        active = 0;
        ramping = 1;
    }
    if (ramping) {
        uint8_t left = (uint8_t)(RAMP_MS - ramping);
        for (uint8_t i = 0; i < 3; i++)
            duty[i] = (int16_t)((int32_t)ramp_from[i] * left / (int16_t)RAMP_MS);
        apply();
        ramping = left ? (uint8_t)(ramping + 1) : 0;
        if (!left)
            limited = 0;
    }

    uint16_t edge[3];
    ATOMIC_BLOCK(ATOMIC_RESTORESTATE) {
        for (uint8_t i = 0; i < 3; i++)
            edge[i] = enc_edge_ms[i];
    }
    uint8_t stalled = 0;
    for (uint8_t i = 0; i < 3; i++) {
        int16_t d = duty[i];
        uint16_t mag = (uint16_t)(d < 0 ? -d : d);
        if (mag < STALL_MIN_DUTY)
            stall_ref_ms[i] = now_ms;                     /* not driven hard: nothing to expect */
        else if ((uint16_t)(now_ms - edge[i]) < (uint16_t)(now_ms - stall_ref_ms[i]))
            stall_ref_ms[i] = edge[i];                    /* an edge since: the wheel turns */
        if ((uint16_t)(now_ms - stall_ref_ms[i]) >= STALL_TIMEOUT_MS)
            stalled = 1;
    }
    if (stalled)
        faults |= FAULT_STALL;
    else
        faults &= (uint16_t)~FAULT_STALL;

    if ((uint16_t)(now_ms - enc_window_ms) >= ENC_WINDOW_MS) {
        enc_window_ms += ENC_WINDOW_MS;
        int32_t c[3];
        drive_encoders(c);
        for (uint8_t i = 0; i < 3; i++) {
            enc_rate[i] = (int16_t)(c[i] - enc_prev[i]);
            enc_prev[i] = c[i];
        }
    }
    if (enc_error)
        faults |= FAULT_ENCODER_ERROR;
}

void drive_duty(int16_t out[3])
{
    for (uint8_t i = 0; i < 3; i++)
        out[i] = duty[i];
}

void drive_encoders(int32_t counts[3])
{
    ATOMIC_BLOCK(ATOMIC_RESTORESTATE) {
        for (uint8_t i = 0; i < 3; i++)
            counts[i] = enc_count[i];
    }
}

void drive_encoder_rate(int16_t rate[3])
{
    for (uint8_t i = 0; i < 3; i++)
        rate[i] = enc_rate[i];
}

uint16_t drive_faults(void)
{
    return (uint16_t)(faults | (limited ? FAULT_SPEED_LIMITED : 0));
}

void drive_clear_faults(uint16_t mask)
{
    if (mask & FAULT_ENCODER_ERROR)
        enc_error = 0;
    faults &= (uint16_t)~(mask & FAULT_ENCODER_ERROR);
}
