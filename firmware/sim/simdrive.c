/* simdrive: runs the drive firmware (build/drive.elf) in simavr as a simulated Arduino Mega.
 *
 *  - UART0 is bridged to a pseudo-terminal; its slave path is printed first as "PTY <path>".
 *    Bytes from the pty are fed into the simulated UART one per character time at the
 *    firmware's baud rate; bytes the firmware sends are written back.
 *  - The motor outputs are watched after every instruction. When OCR4A/B/C (PWM duty) or
 *    the direction pins PA0..2 change and then stay unchanged for 200 cycles, a line
 *        PWM <cycle> <duty0> <duty1> <duty2> <dir bits> <rx cycle>
 *    is printed: <cycle> is when the last of the changes happened, <rx cycle> when the
 *    last UART byte before it was completely received (RXC raised): the difference is the
 *    command-to-PWM latency. All times are simulated CPU cycles at 16 MHz.
 *  - An ideal motor model turns each wheel at duty/PWM_TOP * max speed (sign from the
 *    direction pin) and produces x4 quadrature edges on PB0..PB5 at <cpr> counts/rev;
 *    "ENC <cycle> <c0> <c1> <c2>" reports the model's counts every 50 ms.
 *  - --profile ADDR (a function's byte address, as avr-nm prints it):
 *    every call of that function prints "PROF <entry cycle> <cycles to its return>",
 *    interrupts taken meanwhile included.
 *  - "WDT <cycle> <WDTCSR>" whenever the watchdog control register changes.
 *  - Simulated time is throttled to never run ahead of wall-clock time (x --speed), and
 *    never to catch up more than MAX_LAG_S of a lag (the harness descheduled on a loaded
 *    host): simulated time between two moments never exceeds the wall time between them
 *    by more than that, so a host that refreshes its commands every 100 ms of wall time
 *    never looks silent for 200 ms to the firmware. Under load the board runs slower than
 *    real time instead. (simavr alone runs the core as fast as it can; sleep periods
 *    advance in 16-cycle steps.)
 *  - A virtual MPU-6050 gyro (sim/gyro_part.h) answers on the TWI bus at 0x68 (not with
 *    --no-gyro); bumper switches pull PC0..PC3 low when pressed.
 *  - Test-harness commands on stdin, one per line (acknowledged on stdout with the cycle):
 *        RX <hex bytes>       queue bytes on the line right after those already queued: they
 *                             enter the UART back-to-back, one per character time of
 *                             *simulated* time, whatever the host's scheduling; "RXDONE
 *                             <cycle>" when the last has been received
 *        BUMP <hex mask> [ms] press the switches in mask (bit i = PCi), all others released;
 *                             with ms, release them after that much simulated time
 *        GYRO <rad/s>         the gyro's true Z rate (the test adds any bias it wants)
 *        GYRO unplug | plug   the chip stops answering / is plugged in again (powered up afresh)
 *        ADC <ch> <mV> [<swing mV>]
 *                             the voltage on analog input ADC<ch> (PF<ch>, Mega A<ch>), 0..7, in
 *                             millivolts (AVcc = AREF = 5000 mV); all start at 0 V. With a swing,
 *                             successive conversions of that input see mV + swing and mV - swing
 *                             in turn (a ripple only an average over the samples removes)
 *
 * usage: simdrive [--stall WHEEL] [--speed X] [--duration S] [--cpr N] [--max-speed RADS]
 *                 [--pwm-top N] [--profile ADDR] [--no-gyro] firmware.elf
 */
#define _GNU_SOURCE
#include <errno.h>
#include <fcntl.h>
#include <math.h>
#include <pty.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/prctl.h>
#include <termios.h>
#include <time.h>
#include <unistd.h>

#include "avr_adc.h"
#include "avr_ioport.h"
#include "avr_twi.h"
#include "avr_uart.h"
#include "sim_avr.h"
#include "sim_elf.h"
#include "sim_irq.h"

#include "gyro_part.h"

DEFINE_FIFO(uint16_t, uart_fifo);                /* the header only declares the UART FIFO accessors */

#define F_SIM 16000000UL
/* ATmega2560 data-space addresses (avr/iom2560.h) */
#define A_PORTA 0x22
#define A_OCR4AL 0xA8
#define A_WDTCSR 0x60            /* OCR4A L/H, OCR4B L/H, OCR4C L/H: 0xA8..0xAD */
#define SETTLE_CYCLES 200
#define SYNC_CYCLES 800          /* 50 us: pty pumping, throttling, motor model step */
#define ENC_REPORT_CYCLES (F_SIM / 20)
#define MAX_LAG_S 0.002          /* lag beyond this is given up, never caught up */
#define SUPPLY_MV 5000           /* VCC = AVCC = AREF: the Mega's regulated 5 V */

static avr_t *avr;
static avr_uart_t *uart0;
static int pty_master = -1;
static volatile sig_atomic_t stop_flag;

static uint8_t out_buf[4096];
static size_t out_len;
static uint8_t in_buf[1 << 16];                  /* the line: bytes from the pty and from RX commands */
static size_t in_len, in_pos;
static size_t rx_done_at;                        /* in_pos at which the last RX command is complete (0: none) */
static char cmd_buf[1 << 17];                    /* stdin command line being assembled */
static size_t cmd_len;

static avr_cycle_count_t last_rx_cycle;

static int stall_wheel = -1;
static double speed_factor = 1.0;
static double max_seconds = 600.0;
static int cpr = 1200;
static double max_speed = 20.0;
static int pwm_top = 400;
static long profile_addr = -1;

static avr_irq_t *enc_irq[6];
static double wheel_angle[3];
static long enc_count[3];

static void on_signal(int sig) { (void)sig; stop_flag = 1; }

static void logger(avr_t *a, const int level, const char *fmt, va_list ap)
{
    (void)a;
    /* simavr 1.6 does not model Timer4's phase-correct PWM mode 10 and warns on every OCR
     * write; the harness reads the OCR registers directly, so that warning is noise */
    if (level <= LOG_WARNING && !strstr(fmt, "UNSUPPORTED"))
        vfprintf(stderr, fmt, ap);
}

static void uart_out_hook(struct avr_irq_t *irq, uint32_t value, void *param)
{
    (void)irq; (void)param;
    if (out_len < sizeof out_buf)
        out_buf[out_len++] = (uint8_t)value;
}

static void rxc_pending_hook(struct avr_irq_t *irq, uint32_t value, void *param)
{
    (void)irq; (void)param;
    if (value)
        last_rx_cycle = avr->cycle;
}

static void compact_line(void)
{
    if (in_pos) {
        memmove(in_buf, in_buf + in_pos, in_len - in_pos);
        in_len -= in_pos;
        if (rx_done_at)
            rx_done_at -= in_pos;
        in_pos = 0;
    }
}

static void pump_pty(void)
{
    if (out_len) {
        ssize_t n = write(pty_master, out_buf, out_len);
        if (n > 0) {
            memmove(out_buf, out_buf + n, out_len - (size_t)n);
            out_len -= (size_t)n;
        }
    }
    compact_line();
    if (in_len < sizeof in_buf) {
        ssize_t n = read(pty_master, in_buf + in_len, sizeof in_buf - in_len);
        if (n > 0)
            in_len += (size_t)n;
    }
}

/* --- bumpers: PC0..PC3 driven low while pressed (the firmware's pull-ups hold them high) --- */
static avr_irq_t *bump_irq[4];
static avr_cycle_count_t bump_release_at;

static void set_bumpers(uint8_t pressed)
{
    for (int i = 0; i < 4; i++)
        avr_raise_irq(bump_irq[i], (pressed >> i) & 1 ? 0 : 1);
}

/* analog inputs ADC0..ADC8 (the range sensors' RANGE_SLOTS): value (mV) and ripple per channel, applied at the
 * start of each conversion */
#define N_ADC 9
static avr_irq_t *adc_irq;
static double adc_mv[N_ADC], adc_swing[N_ADC];
static uint8_t adc_phase[N_ADC];

static avr_adc_t *adc_io;

static void set_adc_input(int ch)
{
    double mv = adc_mv[ch] + (adc_phase[ch] ? -adc_swing[ch] : adc_swing[ch]);
    mv = mv < 0 ? 0 : mv > SUPPLY_MV ? SUPPLY_MV : mv;
    if (ch < 8)
        avr_raise_irq(adc_irq + ADC_IRQ_ADC0 + ch, (uint32_t)lround(mv));
    else
        adc_io->muxmode[24 + ch] = (avr_adc_mux_t){.kind = ADC_MUX_REF, .src = (unsigned long)lround(mv)};
}

/* simavr 1.6 (Debian) decodes MUX5 on the 2560 and maps ADC8..15 (MUX5:0 = 32..39, ATmega2560 data sheet table
 * 26-4) to single-ended inputs 8..15, but keeps voltages for ADC0..7 only (adc_values[8]): ADC8 would convert
 * whatever follows that array. The harness turns ADC8's mux mode into a fixed "reference" input at the voltage the
 * test sets (set_adc_input), which simavr converts like a pin (mV against the reference). No ripple on it. */
static void patch_adc_high_channels(avr_t *avr)
{
    for (avr_io_t *io = avr->io_port; io; io = io->next)
        if (io->kind && !strcmp(io->kind, "adc"))
            adc_io = (avr_adc_t *)io;                   /* avr_io_t is its first member */
}

static void adc_start_hook(struct avr_irq_t *irq, uint32_t value, void *param)
{
    (void)irq; (void)param;
    union { avr_adc_mux_t mux; uint32_t v; } e = {.v = value};
    if (e.mux.kind == ADC_MUX_SINGLE && e.mux.src < N_ADC && adc_swing[e.mux.src] > 0) {
        adc_phase[e.mux.src] ^= 1;
        set_adc_input(e.mux.src);
    }
}

static void run_command(char *line)
{
    char *arg = strchr(line, ' ');
    if (arg)
        *arg++ = 0;
    if (!strcmp(line, "RX") && arg) {
        compact_line();
        for (char *h = arg; h[0] && h[1] && in_len < sizeof in_buf; h += 2) {
            unsigned v;
            if (sscanf(h, "%2x", &v) != 1)
                break;
            in_buf[in_len++] = (uint8_t)v;
        }
        rx_done_at = in_len;
        printf("RXQUEUED %llu %zu\n", (unsigned long long)avr->cycle, in_len - in_pos);
    } else if (!strcmp(line, "BUMP") && arg) {
        unsigned mask = 0;
        double ms = 0;
        sscanf(arg, "%x %lf", &mask, &ms);
        set_bumpers((uint8_t)mask);
        bump_release_at = ms > 0 ? avr->cycle + (avr_cycle_count_t)(ms * 1e-3 * F_SIM) : 0;
        printf("BUMP %llu %x\n", (unsigned long long)avr->cycle, mask);
    } else if (!strcmp(line, "GYRO") && arg) {
        if (!strcmp(arg, "unplug") || !strcmp(arg, "plug"))
            gyro_part_unplug(!strcmp(arg, "unplug"));
        else
            gyro_part_set_rate(atof(arg));
        printf("GYRO %llu %s\n", (unsigned long long)avr->cycle, arg);
    } else if (!strcmp(line, "ADC") && arg) {
        int ch = -1;
        double mv = -1, swing = 0;
        if (sscanf(arg, "%d %lf %lf", &ch, &mv, &swing) >= 2 && ch >= 0 && ch < N_ADC && mv >= 0 && mv <= SUPPLY_MV
            && swing >= 0 && (ch < 8 || swing == 0)) {
            adc_mv[ch] = mv;
            adc_swing[ch] = swing;
            set_adc_input(ch);
            printf("ADC %llu %d %.0f %.0f\n", (unsigned long long)avr->cycle, ch, mv, swing);
        } else {
            fprintf(stderr, "simdrive: ADC expects <channel 0..8> <millivolts 0..%d> [<swing mV>, channels 0..7], got %s\n",
                    SUPPLY_MV, arg);
        }
    } else {
        fprintf(stderr, "simdrive: unknown command %s\n", line);
    }
}

static void pump_commands(void)
{
    ssize_t n = read(STDIN_FILENO, cmd_buf + cmd_len, sizeof cmd_buf - 1 - cmd_len);
    if (n <= 0)
        return;
    cmd_len += (size_t)n;
    char *nl;
    while ((nl = memchr(cmd_buf, '\n', cmd_len))) {
        *nl = 0;
        run_command(cmd_buf);
        cmd_len -= (size_t)(nl + 1 - cmd_buf);
        memmove(cmd_buf, nl + 1, cmd_len);
    }
    if (cmd_len == sizeof cmd_buf - 1)
        cmd_len = 0;                             /* an over-long line: drop it */
}

/* The line: one byte enters the simulated UART per character time, and only into an empty
 * receive FIFO. (Keeping many bytes queued in simavr 1.6's UART FIFO stalled its receive
 * pump for milliseconds at a time, which the firmware rightly saw as inter-byte gaps.) */
static avr_cycle_count_t next_rx_cycle;

static void feed_line(void)
{
    if (in_pos < in_len && avr->cycle >= next_rx_cycle && avr_regbit_get(avr, uart0->rxen)
        && uart_fifo_isempty(&uart0->input)) {
        avr_raise_irq(uart0->io.irq + UART_IRQ_INPUT, in_buf[in_pos++]);
        next_rx_cycle = avr->cycle + (uart0->cycles_per_byte ? uart0->cycles_per_byte : 1);
        if (rx_done_at && in_pos == rx_done_at) {
            rx_done_at = 0;
            printf("RXDONE %llu\n", (unsigned long long)avr->cycle);
        }
    }
}

static void set_encoder_pins(int i)
{
    /* position in the cycle 00 -> 10 -> 11 -> 01 as (A, B) */
    static const uint8_t A[4] = {0, 1, 1, 0}, B[4] = {0, 0, 1, 1};
    int pos = (int)(enc_count[i] & 3);
    avr_raise_irq(enc_irq[2 * i], A[pos]);
    avr_raise_irq(enc_irq[2 * i + 1], B[pos]);
}

static void motor_step(double dt)
{
    uint8_t dir = avr->data[A_PORTA];
    for (int i = 0; i < 3; i++) {
        uint16_t ocr = (uint16_t)(avr->data[A_OCR4AL + 2 * i] | (avr->data[A_OCR4AL + 2 * i + 1] << 8));
        if (ocr > pwm_top)
            ocr = (uint16_t)pwm_top;
        double w = (double)ocr / pwm_top * max_speed * ((dir >> i) & 1 ? 1.0 : -1.0);
        if (i == stall_wheel)
            w = 0.0;
        wheel_angle[i] += w * dt;
        long target = (long)floor(wheel_angle[i] / (2.0 * M_PI) * cpr);
        /* at most one quadrature step per wheel per step, as a real encoder would */
        if (target > enc_count[i]) {
            enc_count[i]++;
            set_encoder_pins(i);
        } else if (target < enc_count[i]) {
            enc_count[i]--;
            set_encoder_pins(i);
        }
    }
}

static double wall_seconds(const struct timespec *t0)
{
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return (double)(t.tv_sec - t0->tv_sec) + 1e-9 * (double)(t.tv_nsec - t0->tv_nsec);
}

static void no_sleep(avr_t *a, avr_cycle_count_t how_long) { (void)a; (void)how_long; }

#define WAKE_CYCLES 16
static avr_cycle_count_t wake_tick(avr_t *a, avr_cycle_count_t when, void *param)
{
    (void)a; (void)param;
    return when + WAKE_CYCLES;
}

static void usage(void)
{
    fprintf(stderr, "usage: simdrive [--stall WHEEL] [--speed X] [--duration S] [--cpr N] "
                    "[--max-speed RADS] [--pwm-top N] [--profile ADDR] [--no-gyro] firmware.elf\n");
    exit(2);
}

int main(int argc, char **argv)
{
    const char *elf = NULL;
    int with_gyro = 1;
    for (int i = 1; i < argc; i++) {
        if (!strcmp(argv[i], "--stall") && i + 1 < argc) stall_wheel = atoi(argv[++i]);
        else if (!strcmp(argv[i], "--speed") && i + 1 < argc) speed_factor = atof(argv[++i]);
        else if (!strcmp(argv[i], "--duration") && i + 1 < argc) max_seconds = atof(argv[++i]);
        else if (!strcmp(argv[i], "--cpr") && i + 1 < argc) cpr = atoi(argv[++i]);
        else if (!strcmp(argv[i], "--max-speed") && i + 1 < argc) max_speed = atof(argv[++i]);
        else if (!strcmp(argv[i], "--pwm-top") && i + 1 < argc) pwm_top = atoi(argv[++i]);
        else if (!strcmp(argv[i], "--profile") && i + 1 < argc) profile_addr = strtol(argv[++i], NULL, 0);
        else if (!strcmp(argv[i], "--no-gyro")) with_gyro = 0;
        else if (argv[i][0] == '-') usage();
        else elf = argv[i];
    }
    if (!elf || speed_factor <= 0 || cpr <= 0 || pwm_top <= 0)
        usage();
    setvbuf(stdout, NULL, _IOLBF, 0);
    prctl(PR_SET_PDEATHSIG, SIGTERM);            /* never outlive the test that started us */
    signal(SIGTERM, on_signal);
    signal(SIGINT, on_signal);
    avr_global_logger_set(logger);

    elf_firmware_t fw;
    memset(&fw, 0, sizeof fw);
    if (elf_read_firmware(elf, &fw) != 0) {
        fprintf(stderr, "simdrive: cannot read firmware %s\n", elf);
        return 1;
    }
    strcpy(fw.mmcu, "atmega2560");
    fw.frequency = F_SIM;
    avr = avr_make_mcu_by_name(fw.mmcu);
    if (!avr) {
        fprintf(stderr, "simdrive: simavr has no atmega2560 core\n");
        return 1;
    }
    avr_init(avr);
    avr_load_firmware(avr, &fw);
    avr->vcc = avr->avcc = avr->aref = SUPPLY_MV;      /* simavr's ADC scales readings by these (mV) */
    avr->sleep = no_sleep;                       /* we throttle against the wall clock ourselves */
    /* simavr advances a sleeping core to its next cycle timer *before* servicing the interrupt
     * that should wake it, which would delay wake-ups by up to a tick period (1 ms here) and
     * let two encoder edges pass before the ISR reads the pins. A 16-cycle periodic timer
     * keeps the simulated wake-up latency <= 1 us (costs ~1 M cheap callbacks per sim second). */
    avr_cycle_timer_register(avr, WAKE_CYCLES, wake_tick, NULL);

    for (avr_io_t *io = avr->io_port; io; io = io->next)
        if (!strcmp(io->kind, "uart") && ((avr_uart_t *)io)->name == '0')
            uart0 = (avr_uart_t *)io;
    if (!uart0) {
        fprintf(stderr, "simdrive: no UART0 in the simulated core\n");
        return 1;
    }
    uint32_t flags = 0;                          /* no stdout echo, no poll sleeping */
    avr_ioctl(avr, AVR_IOCTL_UART_SET_FLAGS('0'), &flags);
    avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_OUTPUT),
                            uart_out_hook, NULL);
    avr_irq_register_notify(&uart0->rxc.irq[AVR_INT_IRQ_PENDING], rxc_pending_hook, NULL);
    for (int p = 0; p < 6; p++)
        enc_irq[p] = avr_io_getirq(avr, AVR_IOCTL_IOPORT_GETIRQ('B'), p);
    /* the encoders drive their lines: without this, the firmware enabling its pull-ups
     * would make simavr read the (still low) encoder lines as high */
    avr_ioport_external_t ext = {.name = 'B', .mask = 0x3F, .value = 0x00};
    avr_ioctl(avr, AVR_IOCTL_IOPORT_SET_EXTERNAL('B'), &ext);
    for (int i = 0; i < 3; i++)
        set_encoder_pins(i);
    for (int p = 0; p < 4; p++)
        bump_irq[p] = avr_io_getirq(avr, AVR_IOCTL_IOPORT_GETIRQ('C'), p);
    avr_ioport_external_t ext_c = {.name = 'C', .mask = 0x0F, .value = 0x0F};   /* released: high */
    avr_ioctl(avr, AVR_IOCTL_IOPORT_SET_EXTERNAL('C'), &ext_c);
    set_bumpers(0);
    if (with_gyro)
        gyro_part_attach(avr, AVR_IOCTL_TWI_GETIRQ(0));
    adc_irq = avr_io_getirq(avr, AVR_IOCTL_ADC_GETIRQ, 0);
    patch_adc_high_channels(avr);
    avr_irq_register_notify(adc_irq + ADC_IRQ_OUT_TRIGGER, adc_start_hook, NULL);
    for (int ch = 0; ch < N_ADC; ch++)
        set_adc_input(ch);
    fcntl(STDIN_FILENO, F_SETFL, fcntl(STDIN_FILENO, F_GETFL) | O_NONBLOCK);

    int slave;
    char name[256];
    if (openpty(&pty_master, &slave, name, NULL, NULL) != 0) {
        perror("simdrive: openpty");
        return 1;
    }
    struct termios tio;
    tcgetattr(slave, &tio);
    cfmakeraw(&tio);
    tcsetattr(slave, TCSANOW, &tio);
    fcntl(pty_master, F_SETFL, fcntl(pty_master, F_GETFL) | O_NONBLOCK);
    printf("PTY %s\n", name);                    /* slave stays open: the master never sees a hang-up */

    struct timespec t0;
    clock_gettime(CLOCK_MONOTONIC, &t0);
    uint8_t snap[7], cur[7];
    memset(snap, 0, sizeof snap);
    avr_cycle_count_t changed_at = 0, next_sync = SYNC_CYCLES, next_enc = ENC_REPORT_CYCLES;
    int settling = 0;
    int in_profiled = 0;
    unsigned prof_sp = 0;
    avr_cycle_count_t prof_start = 0;
    int state = cpu_Running;

    while (!stop_flag) {
        state = avr_run(avr);
        if (state == cpu_Done || state == cpu_Crashed)
            break;

        if (profile_addr >= 0) {
            /* 3-byte return address on the 2560: the function has returned when SP is 3 above
             * its value at entry */
            unsigned sp = avr->data[0x5D] | (avr->data[0x5E] << 8);
            if (!in_profiled && avr->pc == (avr_flashaddr_t)profile_addr) {
                in_profiled = 1;
                prof_sp = sp;
                prof_start = avr->cycle;
            } else if (in_profiled && sp == prof_sp + 3) {
                in_profiled = 0;
                printf("PROF %llu %llu\n", (unsigned long long)prof_start,
                       (unsigned long long)(avr->cycle - prof_start));
            }
        }

        feed_line();

        memcpy(cur, &avr->data[A_OCR4AL], 6);
        cur[6] = avr->data[A_PORTA] & 0x07;
        if (memcmp(cur, snap, sizeof cur)) {
            memcpy(snap, cur, sizeof snap);
            changed_at = avr->cycle;
            settling = 1;
        } else if (settling && avr->cycle - changed_at >= SETTLE_CYCLES) {
            settling = 0;
            printf("PWM %llu %u %u %u %u %llu\n", (unsigned long long)changed_at,
                   snap[0] | (snap[1] << 8), snap[2] | (snap[3] << 8), snap[4] | (snap[5] << 8),
                   snap[6], (unsigned long long)last_rx_cycle);
        }

        if (avr->cycle >= next_sync) {
            avr_cycle_count_t steps = (avr->cycle - next_sync) / SYNC_CYCLES + 1;
            next_sync += steps * SYNC_CYCLES;
            motor_step((double)(steps * SYNC_CYCLES) / F_SIM);
            pump_pty();
            pump_commands();
            if (bump_release_at && avr->cycle >= bump_release_at) {
                bump_release_at = 0;
                set_bumpers(0);
                printf("BUMP %llu 0\n", (unsigned long long)avr->cycle);
            }
            double sim_s = (double)avr->cycle / F_SIM;
            static double given_up;                  /* wall seconds of lag not to catch up */
            double ahead = sim_s / speed_factor - (wall_seconds(&t0) - given_up);
            if (ahead < -MAX_LAG_S)
                given_up += -ahead - MAX_LAG_S;
            if (ahead > 0.0005) {
                struct timespec d = {0, (long)(ahead * 1e9)};
                nanosleep(&d, NULL);
            }
            if (sim_s > max_seconds)
                break;
            static int wdtcsr = -1;
            if (avr->data[A_WDTCSR] != wdtcsr) {
                wdtcsr = avr->data[A_WDTCSR];
                printf("WDT %llu %d\n", (unsigned long long)avr->cycle, wdtcsr);
            }
        }
        if (avr->cycle >= next_enc) {
            next_enc += ENC_REPORT_CYCLES;
            printf("ENC %llu %ld %ld %ld\n", (unsigned long long)avr->cycle,
                   enc_count[0], enc_count[1], enc_count[2]);
        }
    }
    printf("END %llu %d\n", (unsigned long long)avr->cycle, state);
    return state == cpu_Crashed ? 1 : 0;
}
