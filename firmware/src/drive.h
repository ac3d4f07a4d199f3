/* Motor outputs (3 H-bridge channels: PWM + direction), inverse kinematics, command
 * watchdog ramp, quadrature encoders. Pin map: firmware/README.md. */
#ifndef DRIVE_H
#define DRIVE_H

#include <stdint.h>

void drive_init(void);
/* Body twist (m/s, m/s, rad/s, robot frame) -> wheel duties, applied at once.
 * Returns 1 if the wheel speeds were scaled down to MAX_WHEEL_SPEED. */
uint8_t drive_set_twist(float vx, float vy, float omega, uint16_t now_ms);
void drive_stop(void);                       /* zero duty on all channels, at once */
/* 1 kHz housekeeping: command watchdog ramp, encoder windows, stall detection. */
void drive_tick(uint16_t now_ms);

void drive_duty(int16_t out[3]);             /* applied signed duty, counts of PWM_TOP */
void drive_encoders(int32_t counts[3]);      /* cumulative x4 counts */
void drive_encoder_rate(int16_t rate[3]);    /* counts in the last ENC_WINDOW_MS */
uint16_t drive_faults(void);                 /* FAULT_CMD_TIMEOUT | SPEED_LIMITED | STALL | ENCODER_ERROR */
void drive_clear_faults(uint16_t mask);

#endif
