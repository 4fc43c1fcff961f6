/* antenna_sim: the shipped firmware (main.c, unmodified .elf) running in simavr, in the loop.
 *
 *   antenna_sim [options] FIRMWARE.elf COUNTS
 *
 * COUNTS is a text file of ADC counts, one sample a line: "x y" (0..1023 each). The harness
 * feeds them to the firmware's own conversions: whenever the firmware's Timer1 compare-match B
 * flag rises (the ADC's hardware trigger, ADTS = 101), sample i is put on ADC0 (x) and ADC1 (y)
 * as millivolts of a 5 V AVcc; the firmware converts, queues and frames it as on the board. After
 * the last line no further conversion is triggered and the run ends once the UART has been idle
 * for IDLE_END_MS (the firmware's queue is then empty).
 *
 * simavr 1.6 implements only the free-running ADC auto trigger, so the harness wires the trigger
 * itself: the compare-B interrupt flag's "pending" IRQ rises exactly when OCF1B is set, and the
 * firmware clears OCF1B in its ADC interrupt; a rising edge of that flag starts a conversion (the
 * ADC ignores it while one is running), which is the datasheet's rule for auto triggering.
 *
 * Every byte the UART shifts out (250000 baud, simavr times each byte at 10 bit times) is written
 * to file descriptor --fd (default 1): a pseudo-terminal's master end when `snn-antenna emulate
 * --firmware` runs it. The simulated clock is paced to the wall clock unless --fast.
 *
 * Back-pressure: while the UART is held, the firmware reads UCSR0A with UDRE0 clear (the data
 * register stays "busy"), so its main loop waits and the ADC interrupt keeps queueing until the
 * 32-entry queue is full. The UART is held
 *   - during each --hold-uart AT_MS:FOR_MS window of simulated time (a line that stalls), and
 *   - paced: while OUT_HIGH bytes wait because the reader does not take them (a full pty).
 * With --fast a full pty pauses the whole simulation instead (as fast as the reader takes it).
 *
 * --reset-at AT_MS resets the MCU (simavr's avr_reset: the registers, RAM and peripherals, as the
 * RESET pin does) at that simulated time: the firmware boots again, sends its boot frame and
 * counts from 0, while the stimulus goes on (the world does not wait for the board).
 *
 * At the end one JSON line on stderr: simulated and wall seconds, their ratio, the fraction of
 * wall time the simulation was busy, samples fed, bytes sent, the UART line load, held time, and
 * why it stopped early (null, "stopped by a signal" (SIGINT, SIGTERM, or its parent gone), or the reader leaving: exit status 3).
 */
#define _GNU_SOURCE
#include <errno.h>
#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <stdarg.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include <avr_adc.h>
#include <avr_timer.h>
#include <avr_uart.h>
#include <sim_avr.h>
#include <sim_elf.h>
#include <sim_io.h>

#define F_CPU_HZ 16000000UL
#define AVCC_MV 5000u
#define MAX_COUNTS 1023u
#define TICK_CYCLES (F_CPU_HZ / 1000)   /* pace, flush and look at the reader every 1 ms */
#define IDLE_END_MS 5
#define OUT_SIZE 4096
#define OUT_HIGH 64                      /* a USB-serial adapter's few dozen bytes of buffer */
#define MAX_HOLDS 16

enum { EXIT_OK = 0, EXIT_USAGE = 2, EXIT_PEER_GONE = 3, EXIT_SIM = 4 };

static struct {
    avr_t *avr;
    uint16_t (*counts)[2];
    size_t n_counts, fed;
    int fd, fast;
    uint8_t out[OUT_SIZE];
    size_t out_len;
    uint64_t bytes_sent, held_cycles, last_tx_cycle;
    struct { uint64_t from, to; } holds[MAX_HOLDS];
    int n_holds;
    uint64_t resets[MAX_HOLDS];          /* cycles at which the MCU is reset, in order */
    int n_resets, next_reset;
    avr_irq_t *adc_irq;                  /* the ADC's IRQs: ADC0..7, IN_TRIGGER, OUT_TRIGGER */
    avr_io_read_t ucsra_read;            /* the UART's own reader of UCSR0A, wrapped below */
    void *ucsra_param;
    uint8_t udre_mask, udre_hidden;
    volatile sig_atomic_t stop;
    int peer_gone;
} sim;

static void fail(int code, const char *fmt, const char *what)
{
    fprintf(stderr, "antenna_sim: ");
    fprintf(stderr, fmt, what);
    fputc('\n', stderr);
    exit(code);
}

static double now_s(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + ts.tv_nsec * 1e-9;
}

/* ---- the ADC: the firmware's trigger, the stimulus's counts ---- */

static uint32_t counts_to_mv(uint16_t counts)
{
    /* simavr converts floor(mV * 1023 / AVcc): the smallest mV that gives back these counts */
    return ((uint32_t)counts * AVCC_MV + MAX_COUNTS - 1) / MAX_COUNTS;
}

static void on_compare_b_flag(avr_irq_t *irq, uint32_t value, void *param)
{
    (void)param;
    if (value && !irq->value && sim.fed < sim.n_counts)     /* OCF1B rises: trigger */
        avr_raise_irq(sim.adc_irq + ADC_IRQ_IN_TRIGGER, 1);
}

static void on_conversion_start(avr_irq_t *irq, uint32_t value, void *param)
{
    (void)irq, (void)param;
    union { avr_adc_mux_t mux; uint32_t v; } e = { .v = value };
    if (e.mux.kind != ADC_MUX_SINGLE || e.mux.src != 0 || sim.fed >= sim.n_counts)
        return;
    /* X starts a sample: both axes are held at this instant's values (Y converts ~104 us on) */
    const uint16_t *xy = sim.counts[sim.fed++];
    avr_raise_irq(sim.adc_irq + ADC_IRQ_ADC0, counts_to_mv(xy[0]));
    avr_raise_irq(sim.adc_irq + ADC_IRQ_ADC1, counts_to_mv(xy[1]));
}

/* ---- the UART: bytes out, and the hold ---- */

static int held(void)
{
    uint64_t c = sim.avr->cycle;
    for (int i = 0; i < sim.n_holds; i++)
        if (c >= sim.holds[i].from && c < sim.holds[i].to)
            return 1;
    return !sim.fast && sim.out_len >= OUT_HIGH;
}

static uint8_t read_ucsra(avr_t *avr, avr_io_addr_t addr, void *param)
{
    (void)param;
    int hold = held();
    if (!hold && sim.udre_hidden) {      /* give back the UDRE0 the hold kept from the firmware */
        avr->data[addr] |= sim.udre_mask;
        sim.udre_hidden = 0;
    }
    uint8_t v = sim.ucsra_read(avr, addr, sim.ucsra_param);
    if (hold && (v & sim.udre_mask)) {
        sim.udre_hidden = 1;
        v &= (uint8_t)~sim.udre_mask;
    }
    return v;
}

static void on_uart_byte(avr_irq_t *irq, uint32_t value, void *param)
{
    (void)irq, (void)param;
    if (sim.out_len == OUT_SIZE)
        fail(EXIT_SIM, "%s", "output buffer overflow (the hold did not hold)");
    sim.out[sim.out_len++] = (uint8_t)value;
    sim.last_tx_cycle = sim.avr->cycle;
}

/* Write what the reader takes; with wait, until everything is written. */
static void flush_out(int wait)
{
    size_t done = 0;
    while (done < sim.out_len) {
        struct pollfd p = { .fd = sim.fd, .events = POLLOUT };
        if (poll(&p, 1, wait ? 100 : 0) < 0 && errno != EINTR)
            fail(EXIT_SIM, "poll: %s", strerror(errno));
        if (p.revents & (POLLHUP | POLLERR))
            sim.peer_gone = 1;
        if (sim.stop || sim.peer_gone)
            break;
        if (!(p.revents & POLLOUT)) {
            if (wait)
                continue;
            break;
        }
        ssize_t n = write(sim.fd, sim.out + done, sim.out_len - done);
        if (n < 0 && errno == EIO)
            sim.peer_gone = 1;
        else if (n < 0 && errno != EAGAIN && errno != EINTR)
            fail(EXIT_SIM, "write: %s", strerror(errno));
        if (n > 0)
            done += (size_t)n;
    }
    memmove(sim.out, sim.out + done, sim.out_len - done);
    sim.out_len -= done;
    sim.bytes_sent += done;
}

/* ---- set-up ---- */

static avr_io_t *find_io(avr_t *avr, uint32_t ioctl_get)
{
    for (avr_io_t *io = avr->io_port; io; io = io->next)
        if (io->irq_ioctl_get == ioctl_get)
            return io;
    return NULL;
}

static void read_counts(const char *path)
{
    FILE *f = fopen(path, "r");
    if (!f)
        fail(EXIT_USAGE, "cannot open the counts file %s", path);
    size_t cap = 4096;
    sim.counts = malloc(cap * sizeof *sim.counts);
    unsigned x, y;
    int got;
    while ((got = fscanf(f, "%u %u", &x, &y)) == 2) {
        if (x > MAX_COUNTS || y > MAX_COUNTS) {
            fprintf(stderr, "antenna_sim: counts line %zu: %u %u; accepted: 0..1023 each\n",
                    sim.n_counts + 1, x, y);
            exit(EXIT_USAGE);
        }
        if (sim.n_counts == cap)
            sim.counts = realloc(sim.counts, (cap *= 2) * sizeof *sim.counts);
        sim.counts[sim.n_counts][0] = (uint16_t)x;
        sim.counts[sim.n_counts++][1] = (uint16_t)y;
    }
    if (got != EOF || sim.n_counts == 0) {
        fprintf(stderr, "antenna_sim: counts line %zu: not \"x y\" (two integers 0..1023)\n",
                sim.n_counts + 1);
        exit(EXIT_USAGE);
    }
    fclose(f);
}

/* simavr logs to stdout, which may be the data (--fd 1): errors go to stderr, the rest nowhere.
 * ("ADC: unimplemented auto trigger mode: timer_1_compare_match_b" is the gap wired above.) */
static void log_errors(avr_t *avr, const int level, const char *format, va_list ap)
{
    (void)avr;
    if (level <= LOG_ERROR)
        vfprintf(stderr, format, ap);
}

static void on_signal(int sig)
{
    (void)sig;
    sim.stop = 1;
}

static void usage(void)
{
    fprintf(stderr, "usage: antenna_sim [--mcu atmega328p|atmega2560] [--fd N] [--fast] "
                    "[--hold-uart AT_MS:FOR_MS]... [--reset-at AT_MS]... FIRMWARE.elf COUNTS\n");
    exit(EXIT_USAGE);
}

int main(int argc, char **argv)
{
    const char *mcu = "atmega328p";
    sim.fd = 1;
    int i = 1;
    for (; i < argc && strncmp(argv[i], "--", 2) == 0; i++) {
        if (!strcmp(argv[i], "--fast")) {
            sim.fast = 1;
        } else if (!strcmp(argv[i], "--mcu") && i + 1 < argc) {
            mcu = argv[++i];
        } else if (!strcmp(argv[i], "--fd") && i + 1 < argc) {
            sim.fd = atoi(argv[++i]);
        } else if (!strcmp(argv[i], "--hold-uart") && i + 1 < argc && sim.n_holds < MAX_HOLDS) {
            double at_ms, for_ms;
            if (sscanf(argv[++i], "%lf:%lf", &at_ms, &for_ms) != 2 || at_ms < 0 || for_ms <= 0)
                fail(EXIT_USAGE, "--hold-uart %s; accepted: AT_MS:FOR_MS, e.g. 500:50", argv[i]);
            sim.holds[sim.n_holds].from = (uint64_t)(at_ms * (F_CPU_HZ / 1000));
            sim.holds[sim.n_holds++].to = (uint64_t)((at_ms + for_ms) * (F_CPU_HZ / 1000));
        } else if (!strcmp(argv[i], "--reset-at") && i + 1 < argc && sim.n_resets < MAX_HOLDS) {
            double at_ms;
            uint64_t at;
            if (sscanf(argv[++i], "%lf", &at_ms) != 1 || at_ms <= 0
                || (at = (uint64_t)(at_ms * (F_CPU_HZ / 1000)),
                    sim.n_resets && at <= sim.resets[sim.n_resets - 1]))
                fail(EXIT_USAGE, "--reset-at %s; accepted: AT_MS > 0, later than the last", argv[i]);
            sim.resets[sim.n_resets++] = at;
        } else {
            usage();
        }
    }
    if (argc - i != 2)
        usage();
    read_counts(argv[i + 1]);

    avr_global_logger_set(log_errors);
    elf_firmware_t fw;
    memset(&fw, 0, sizeof fw);
    if (elf_read_firmware(argv[i], &fw) != 0)
        fail(EXIT_USAGE, "cannot read the firmware %s", argv[i]);
    snprintf(fw.mmcu, sizeof fw.mmcu, "%s", mcu);
    fw.frequency = F_CPU_HZ;
    fw.avcc = AVCC_MV;
    avr_t *avr = sim.avr = avr_make_mcu_by_name(fw.mmcu);
    if (!avr)
        fail(EXIT_USAGE, "unknown --mcu %s; accepted: atmega328p, atmega2560", mcu);
    avr_init(avr);
    avr_load_firmware(avr, &fw);

    sim.adc_irq = avr_io_getirq(avr, AVR_IOCTL_ADC_GETIRQ, 0);
    avr_timer_t *timer1 = (avr_timer_t *)find_io(avr, AVR_IOCTL_TIMER_GETIRQ('1'));
    avr_uart_t *uart0 = (avr_uart_t *)find_io(avr, AVR_IOCTL_UART_GETIRQ('0'));
    if (!sim.adc_irq || !timer1 || !uart0)
        fail(EXIT_SIM, "%s has no ADC, Timer1 or UART0 in simavr", mcu);
    avr_irq_register_notify(timer1->comp[AVR_TIMER_COMPB].interrupt.irq + AVR_INT_IRQ_PENDING,
                            on_compare_b_flag, NULL);
    avr_irq_register_notify(sim.adc_irq + ADC_IRQ_OUT_TRIGGER, on_conversion_start, NULL);
    avr_irq_register_notify(uart0->io.irq + UART_IRQ_OUTPUT, on_uart_byte, NULL);
    uint32_t flags = 0;                  /* no console echo, no sleeping in UCSR0A polls */
    avr_ioctl(avr, AVR_IOCTL_UART_SET_FLAGS('0'), &flags);
    avr_io_addr_t ucsra = uart0->udrc.raised.reg;
    sim.udre_mask = (uint8_t)(uart0->udrc.raised.mask << uart0->udrc.raised.bit);
    sim.ucsra_read = avr->io[AVR_DATA_TO_IO(ucsra)].r.c;
    sim.ucsra_param = avr->io[AVR_DATA_TO_IO(ucsra)].r.param;
    if (!sim.ucsra_read)
        fail(EXIT_SIM, "%s", "simavr's UART has no UCSR0A reader to wrap");
    avr->io[AVR_DATA_TO_IO(ucsra)].r.c = read_ucsra;

    signal(SIGINT, on_signal);
    signal(SIGTERM, on_signal);
    signal(SIGPIPE, SIG_IGN);
    fcntl(sim.fd, F_SETFL, fcntl(sim.fd, F_GETFL) | O_NONBLOCK);

    pid_t parent = getppid();
    double t0 = now_s(), slept = 0;
    uint64_t next_tick = TICK_CYCLES;
    int state = cpu_Running;
    while (!sim.stop && !sim.peer_gone && state != cpu_Done && state != cpu_Crashed) {
        state = avr_run(avr);
        if (avr->cycle < next_tick)
            continue;
        next_tick += TICK_CYCLES;
        if (sim.next_reset < sim.n_resets && avr->cycle >= sim.resets[sim.next_reset]) {
            sim.next_reset++;
            avr_reset(avr);
        }
        if (held())                      /* held time, to the tick */
            sim.held_cycles += TICK_CYCLES;
        flush_out(sim.fast && sim.out_len >= OUT_HIGH);
        if (!sim.fast) {                 /* pace: simulated time never runs ahead of the wall */
            double before = now_s(), ahead = (double)avr->cycle / F_CPU_HZ - (before - t0);
            if (ahead > 0) {
                struct timespec ts = { 0, (long)(ahead * 1e9) };
                nanosleep(&ts, NULL);
                slept += now_s() - before;   /* as slept: the kernel's slack is not busy time */
            }
        }
        if (getppid() != parent)         /* whoever started us is gone (killed): so are we */
            sim.stop = 1;
        struct pollfd p = { .fd = sim.fd, .events = 0 };
        if (poll(&p, 1, 0) > 0 && (p.revents & (POLLHUP | POLLERR)))
            sim.peer_gone = 1;
        if (sim.fed == sim.n_counts && sim.out_len == 0
            && avr->cycle - sim.last_tx_cycle > IDLE_END_MS * TICK_CYCLES)
            break;
    }
    if (!sim.peer_gone)
        flush_out(1);
    if (state == cpu_Crashed)
        fail(EXIT_SIM, "%s", "the firmware crashed in simavr");
    double wall = now_s() - t0, simulated = (double)avr->cycle / F_CPU_HZ;
    double byte_s = 10.0 / 250000.0;      /* 8N1 at the firmware's 250000 baud */
    fprintf(stderr, "{\"simulated_s\": %.4f, \"wall_s\": %.4f, \"realtime_ratio\": %.3f, "
                    "\"busy_fraction\": %.3f, \"samples_fed\": %zu, \"bytes_sent\": %llu, "
                    "\"line_load\": %.4f, \"held_s\": %.4f, \"stopped\": %s}\n",
            simulated, wall, simulated / wall, (wall - slept) / wall, sim.fed,
            (unsigned long long)sim.bytes_sent, sim.bytes_sent * byte_s / simulated,
            (double)sim.held_cycles / F_CPU_HZ,
            sim.peer_gone ? "\"the reader closed the port\"" : sim.stop ? "\"stopped by a signal\"" : "null");
    return sim.peer_gone ? EXIT_PEER_GONE : EXIT_OK;
}
