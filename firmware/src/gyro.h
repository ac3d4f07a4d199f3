/* MPU-6050-class I2C gyro (address 0x68): yaw rate for the host's odometry. */
#ifndef GYRO_H
#define GYRO_H

#include <stdint.h>

void gyro_init(void);
/* Every 1 ms tick: runs the probe / configuration / sampling transactions (non-blocking),
 * re-probing after a bus error or a missing chip. */
void gyro_tick(uint16_t now_ms);
uint8_t gyro_ok(void);          /* configured, and the last read succeeded */
/* Mean Z rate over the last ENC_WINDOW_MS window, raw counts at GYRO_LSB_PER_DPS_X10 / 10
 * counts per deg/s, chip bias not removed (the host tracks it while the robot stands still);
 * 0 when !gyro_ok(). */
int16_t gyro_rate(void);

#endif
