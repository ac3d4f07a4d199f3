/* Infrared range sensors: up to 9 Sharp GP2Y0A21YK0F-class analog distance sensors (10-80 cm) on
 * ADC0..ADC8 (PF0..PF7 and PK0, Mega A0..A8); sensor i on ADCi looks along robot.ranging.RangeLayout's
 * azimuth i. RANGE_SENSORS (config.h) of them; 0 = none (the ADC stays off). */
#ifndef RANGES_H
#define RANGES_H

#include <stdint.h>

#define RANGE_NO_RETURN  0u     /* reading: nothing within 80 cm (voltage below the 80 cm point) */
#define RANGE_MIN_CM     10u    /* readings are RANGE_MIN_CM..RANGE_MAX_CM, or RANGE_NO_RETURN */
#define RANGE_MAX_CM     80u

void ranges_init(void);
/* Every 1 ms tick: starts a sweep of all channels every RANGE_SAMPLE_MS (conversions chained
 * in the ADC interrupt, never waited for), closes the RANGE_WINDOW_MS averaging window and
 * converts one sensor's mean per tick into centimetres. */
void ranges_tick(uint16_t now_ms);
/* The sensors are configured and every reading comes from a complete window taken after
 * the sensors' power-up time; 0 without sensors. */
uint8_t ranges_ok(void);
/* Distance (cm) per sensor, RANGE_MIN_CM..RANGE_MAX_CM or RANGE_NO_RETURN; slots past
 * RANGE_SENSORS (and all of them while !ranges_ok()) are RANGE_NO_RETURN. */
uint8_t ranges_cm(uint8_t i);

#endif
