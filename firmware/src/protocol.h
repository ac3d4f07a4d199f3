/* Frame layout and message definitions: docs/protocol.md (mirrors src/robot/protocol.py). */
#ifndef PROTOCOL_H
#define PROTOCOL_H

#include <stdint.h>

#define PROTO_SOF            0xA5u
#define PROTO_VERSION        3u
#define PROTO_HEADER_LEN     4u      /* SOF LEN TYPE SEQ */
#define PROTO_CRC_LEN        2u
#define PROTO_MCU_MAX_PAYLOAD 16u    /* commands are short; larger LEN is a length error */

enum msg_type {
    MSG_PING = 0x01, MSG_SET_TWIST = 0x02, MSG_SET_HEADING = 0x03, MSG_STOP = 0x04,
    MSG_GET_TELEMETRY = 0x05, MSG_CLEAR_FAULTS = 0x06,
    MSG_ACK = 0x81, MSG_NAK = 0x82, MSG_PONG = 0x83, MSG_TELEMETRY = 0x84,
};

enum nak_reason { NAK_BAD_LENGTH = 1, NAK_UNKNOWN_TYPE = 2, NAK_BAD_VALUE = 3 };

enum fault_bits {
    FAULT_CMD_TIMEOUT = 1u << 0, FAULT_SPEED_LIMITED = 1u << 1, FAULT_WDT_RESET = 1u << 2,
    FAULT_BROWNOUT_RESET = 1u << 3, FAULT_RX_OVERFLOW = 1u << 4, FAULT_STALL = 1u << 5,
    FAULT_ENCODER_ERROR = 1u << 6,
};

#define ACK_SPEED_LIMITED    0x01u
#define AZIMUTH_LIMIT_MRAD   3142

#define TELEMETRY_LEN        63u
#define RANGE_SLOTS          9u      /* TELEMETRY ranges_cm: one u8 per sensor slot (ADC0..ADC8) */

#define SENSOR_GYRO_OK       0x01u   /* TELEMETRY sensors: the gyro answers and its rate is valid */
#define SENSOR_RANGES_OK     0x02u   /* TELEMETRY sensors: range sensors fitted and ranges_cm valid */
#define PONG_LEN             14u

typedef struct {
    uint8_t type;
    uint8_t seq;
    uint8_t len;
    uint8_t payload[PROTO_MCU_MAX_PAYLOAD];
} frame_t;

#endif
