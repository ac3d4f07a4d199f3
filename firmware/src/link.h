/* Serial link: interrupt-driven UART0 receive ring, resynchronising frame parser, framed replies. */
#ifndef LINK_H
#define LINK_H

#include <stdint.h>
#include "protocol.h"

typedef struct {
    uint16_t rx_frames, crc_errors, length_errors, timeouts, dropped_bytes, naks, rx_overflows, tx_dropped;
} link_stats_t;

extern link_stats_t link_stats;

void link_init(void);
/* Extract the next CRC-valid frame from the receive ring into *out (1) or 0 when none is complete;
 * an incomplete candidate is abandoned after INTERBYTE_TIMEOUT_MS without a byte. */
uint8_t link_poll(frame_t *out);
/* Remember the receive position; link_rx_new() then tells whether bytes arrived since
 * (the main loop sleeps only if none did). */
void link_rx_mark_seen(void);
uint8_t link_rx_new(void);
/* Queue one frame for transmission; 0 (and tx_dropped counted) if the transmit ring lacks room. */
uint8_t link_send(uint8_t type, uint8_t seq, const uint8_t *payload, uint8_t len);
uint8_t link_rx_overflowed(void);   /* 1 once since the last call if the receive ring overflowed */

#endif
