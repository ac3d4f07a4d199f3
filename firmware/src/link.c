/* UART0 link: see link.h and docs/protocol.md. */
#include "config.h"
#include "link.h"
#include "crc16.h"

#include <avr/interrupt.h>
#include <avr/io.h>
#include <util/atomic.h>

link_stats_t link_stats;

/* 256-byte rings indexed by uint8_t: wrap-around is free. The RX ISR owns rx_head, the
 * main loop owns rx_tail; both are single bytes, so reads are atomic. */
static volatile uint8_t rx_buf[256];
static volatile uint8_t rx_head, rx_tail;
static volatile uint16_t rx_last_ms;         /* tick of the last received byte */
static volatile uint8_t rx_overflow_flag;
static uint8_t rx_seen;                      /* rx_head at the last link_rx_mark_seen() */

static volatile uint8_t tx_buf[256];        /* replies; one that does not fit is dropped, never waited for */
static volatile uint8_t tx_head, tx_tail;

extern volatile uint16_t g_ms;               /* main.c: 1 kHz tick */

void link_init(void)
{
    /* U2X: UBRR = F_CPU / (8 * baud) - 1, rounded */
    const uint16_t ubrr = (uint16_t)((F_CPU + 4UL * UART_BAUD) / (8UL * UART_BAUD) - 1UL);
    UBRR0H = (uint8_t)(ubrr >> 8);
    UBRR0L = (uint8_t)ubrr;
    UCSR0A = _BV(U2X0);
    UCSR0C = _BV(UCSZ01) | _BV(UCSZ00);                  /* 8N1 */
    UCSR0B = _BV(RXEN0) | _BV(TXEN0) | _BV(RXCIE0);
}

ISR(USART0_RX_vect)
{
    uint8_t status = UCSR0A;          /* read flags before UDR0 */
    uint8_t b = UDR0;
    uint8_t next = (uint8_t)(rx_head + 1);
    if (status & (_BV(FE0) | _BV(DOR0))) {
        /* a framing error corrupts the byte: keep it (the CRC rejects the frame) but count overruns */
        if (status & _BV(DOR0)) {
            link_stats.rx_overflows++;
            rx_overflow_flag = 1;
        }
    }
    if (next == rx_tail) {
        link_stats.rx_overflows++;
        rx_overflow_flag = 1;
    } else {
        rx_buf[rx_head] = b;
        rx_head = next;
    }
    rx_last_ms = g_ms;
}

ISR(USART0_UDRE_vect)
{
    if (tx_head == tx_tail) {
        UCSR0B &= (uint8_t)~_BV(UDRIE0);
        return;
    }
    UDR0 = tx_buf[tx_tail];
    tx_tail = (uint8_t)(tx_tail + 1);
}

static void tx_put(uint8_t b)
{
    tx_buf[tx_head] = b;
    tx_head = (uint8_t)(tx_head + 1);
}

uint8_t link_send(uint8_t type, uint8_t seq, const uint8_t *payload, uint8_t len)
{
    /* Never block the control loop on the line: if the host floods requests faster than
     * their replies can be sent, a reply that does not fit is dropped (the host resends). */
    uint8_t room = (uint8_t)(tx_tail - tx_head - 1);
    if (room < (uint16_t)len + PROTO_HEADER_LEN + PROTO_CRC_LEN) {
        link_stats.tx_dropped++;
        return 0;
    }
    uint16_t crc = CRC16_INIT;
    crc = crc16_update(crc, len);
    crc = crc16_update(crc, type);
    crc = crc16_update(crc, seq);
    tx_put(PROTO_SOF);
    tx_put(len);
    tx_put(type);
    tx_put(seq);
    for (uint8_t i = 0; i < len; i++) {
        crc = crc16_update(crc, payload[i]);
        tx_put(payload[i]);
    }
    tx_put((uint8_t)crc);
    tx_put((uint8_t)(crc >> 8));
    UCSR0B |= _BV(UDRIE0);
    return 1;
}

void link_rx_mark_seen(void)
{
    rx_seen = rx_head;
}

uint8_t link_rx_new(void)
{
    return rx_head != rx_seen;
}

uint8_t link_rx_overflowed(void)
{
    uint8_t f;
    ATOMIC_BLOCK(ATOMIC_RESTORESTATE) {
        f = rx_overflow_flag;
        rx_overflow_flag = 0;
    }
    return f;
}

/* The parse window always starts at rx_tail; bytes leave the ring only when a frame is
 * accepted or a start byte is rejected, so rejecting a candidate rescans the bytes after
 * its start byte (a real frame hidden behind garbage is found). */
uint8_t link_poll(frame_t *out)
{
    for (;;) {
        uint8_t tail = rx_tail;
        uint8_t avail = (uint8_t)(rx_head - tail);
        if (avail == 0)
            return 0;
        if (rx_buf[tail] != PROTO_SOF) {
            rx_tail = (uint8_t)(tail + 1);
            link_stats.dropped_bytes++;
            continue;
        }
        if (avail >= 2) {
            uint8_t len = rx_buf[(uint8_t)(tail + 1)];
            if (len > PROTO_MCU_MAX_PAYLOAD) {
                link_stats.length_errors++;
                rx_tail = (uint8_t)(tail + 1);
                continue;
            }
            uint8_t total = (uint8_t)(len + PROTO_HEADER_LEN + PROTO_CRC_LEN);
            if (avail >= total) {
                uint16_t crc = CRC16_INIT;
                uint8_t i = (uint8_t)(tail + 1);
                uint8_t end = (uint8_t)(tail + PROTO_HEADER_LEN + len);
                for (; i != end; i++)
                    crc = crc16_update(crc, rx_buf[i]);
                uint16_t got = (uint16_t)rx_buf[end] | ((uint16_t)rx_buf[(uint8_t)(end + 1)] << 8);
                if (got != crc) {
                    link_stats.crc_errors++;
                    rx_tail = (uint8_t)(tail + 1);
                    continue;
                }
                out->len = len;
                out->type = rx_buf[(uint8_t)(tail + 2)];
                out->seq = rx_buf[(uint8_t)(tail + 3)];
                for (uint8_t k = 0; k < len; k++)
                    out->payload[k] = rx_buf[(uint8_t)(tail + PROTO_HEADER_LEN + k)];
                rx_tail = (uint8_t)(tail + total);
                link_stats.rx_frames++;
                return 1;
            }
        }
        /* incomplete candidate: abandon it only after the inter-byte timeout. The clock is read
         * together with the last byte's tick: a "now" taken before this call could be older than
         * a byte received meanwhile (a tick and a byte during a long rescan), and the wrapped
         * difference was a spurious timeout that dropped a valid frame's start byte. */
        uint16_t last, now;
        ATOMIC_BLOCK(ATOMIC_RESTORESTATE) {
            last = rx_last_ms;
            now = g_ms;
        }
        if ((uint16_t)(now - last) >= INTERBYTE_TIMEOUT_MS) {
            link_stats.timeouts++;
            rx_tail = (uint8_t)(tail + 1);
            continue;
        }
        return 0;
    }
}
