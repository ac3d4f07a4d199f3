/* Build-time configuration of the omni-drive controller (ATmega2560, 16 MHz).
 *
 * Geometry and limits must equal robot.kinematics.OmniDriveParams (Python); the
 * simavr tests (tests/test_firmware_sim.py) check this file against it and the PWM
 * the firmware produces against the Python inverse kinematics. SI units. */
#ifndef CONFIG_H
#define CONFIG_H

#ifndef F_CPU
#define F_CPU 16000000UL
#endif

#define FW_VERSION          0x0100u   /* major << 8 | minor */
#define UART_BAUD           115200UL  /* 8N1, U2X: UBRR 16 -> 117647 Bd (+2.1 %, same as the Mega's USB bridge) */

/* --- kinematics (robot.kinematics.OmniDriveParams) --- */
#define WHEEL_RADIUS_M      0.05f     /* m */
#define BASE_RADIUS_M       0.125f    /* m, centre to wheel contact */
#define WHEEL0_ANGLE_DEG    60.0f     /* CCW from +x: front-left */
#define WHEEL1_ANGLE_DEG    180.0f    /* rear */
#define WHEEL2_ANGLE_DEG    300.0f    /* front-right */
#define MAX_WHEEL_SPEED     20.0f     /* rad/s at 100 % duty (open loop) and the speed limit */

/* --- motor outputs --- */
#define PWM_TOP             400u      /* Timer4 phase-correct PWM, TOP = ICR4: 16 MHz / (2 * 400) = 20 kHz */

/* --- safety --- */
#define CMD_TIMEOUT_MS      300u      /* command watchdog: ramp down after more than this without a motion command */
#define RAMP_STEP_PER_MS    4u        /* duty counts per ms while ramping down: 400 -> 0 in 100 ms */
#define INTERBYTE_TIMEOUT_MS 5u       /* abandon an incomplete frame after this long without a byte */
#define STALL_TIMEOUT_MS    500u      /* no encoder edge for this long while driven ... */
#define STALL_MIN_DUTY      (PWM_TOP / 4u) /* ... at >= 25 % duty -> STALL */

/* --- encoders --- */
#define ENC_WINDOW_MS       50u       /* telemetry encoder_rate window */

#endif
