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

#define FW_VERSION          0x0300u   /* major << 8 | minor */
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
/* Command watchdog (requirement: duties at zero within 300 ms of the last valid command, at any duty):
 * the ramp starts after more than CMD_TIMEOUT_MS without a motion command (200..201 ms with the
 * 1 ms tick) and brings every channel linearly to zero in RAMP_MS ticks, all in proportion (the
 * direction of motion is kept): zero 290..291 ms after the command, whatever the duty. */
#define CMD_TIMEOUT_MS      200u
#define RAMP_MS             90u
#define STOP_DEADLINE_MS    300u      /* documented bound: CMD_TIMEOUT_MS + 1 + RAMP_MS must not exceed it */
#define INTERBYTE_TIMEOUT_MS 5u       /* abandon an incomplete frame after this long without a byte */
#define STALL_TIMEOUT_MS    500u      /* no encoder edge for this long while driven ... */
#define STALL_MIN_DUTY      (PWM_TOP / 4u) /* ... at >= 25 % duty -> STALL */

/* --- sensors --- */
#define TWI_HZ              400000UL  /* I2C clock (MPU-6050: fast mode, 400 kHz) */
#define GYRO_FS_SEL         1u        /* +-500 deg/s: covers the 8 rad/s (458 deg/s) turn at the wheel-speed limit */
#define GYRO_LSB_PER_DPS_X10 655u     /* 65.5 LSB per deg/s at FS_SEL 1 (MPU-6050 datasheet, table 6.1) */
#define GYRO_PERIOD_MS      5u        /* 200 Hz sampling, averaged over the ENC_WINDOW_MS window */
#define GYRO_BUS_TIMEOUT_MS 3u        /* a transaction takes ~0.15 ms at 400 kHz; longer = hung bus */
#define GYRO_RETRY_MS       1000u     /* re-probe a missing or failed gyro this often */
#define BUMPER_DEBOUNCE_MS  5u        /* a switch level must hold this long (contact bounce) */
/* Infrared range sensors (Sharp GP2Y0A21YK0F, 10-80 cm) on ADC0..ADC(RANGE_SENSORS-1): as many as
 * robot.ranging.RangeLayout has (the host checks the count in PONG); 0 = none, ADC left off.
 * Override at build time: make EXTRA_CFLAGS=-DRANGE_SENSORS=0 */
#ifndef RANGE_SENSORS
#define RANGE_SENSORS       9u
#endif
#define RANGE_SAMPLE_MS     2u        /* one sweep of all sensors this often ... */
#define RANGE_WINDOW_MS     50u       /* ... averaged over this window (25 samples per sensor) */
#define RANGE_WARMUP_MS     53u       /* data sheet timing chart: first output valid after 38.3 + 9.6 + 5 ms */

/* --- encoders --- */
#define ENC_WINDOW_MS       50u       /* telemetry encoder_rate window */

#endif
