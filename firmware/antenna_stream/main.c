/* antenna_stream: the sensor board's firmware (ATmega328P / ATmega2560 at 16 MHz).
 *
 * Timer1 compare-match B triggers the ADC 1000 times a second (no software jitter); the ADC
 * interrupt converts axis X (ADC0) then axis Y (ADC1) and queues the pair with its sequence number.
 * The main loop frames queued samples (COBS + CRC-16/XMODEM, frame.c) and sends them at 250000
 * baud, 8N1: 10 bytes per frame, 40 % of the line.
 *
 * A sample that finds the queue full is dropped but still consumes its sequence number, so the host
 * sees the loss as a gap instead of a silent time warp. At reset the board sends a boot frame
 * (frame.h) before its first sample, whose sequence number is 0: the host counts a new session,
 * never a gap or duplicates, however far the old count had gone.
 */
#include <avr/interrupt.h>
#include <avr/io.h>
#include <util/atomic.h>

#include "frame.h"

#ifndef F_CPU
#error "F_CPU must be defined (the Makefile passes -DF_CPU)"
#endif

#define BAUD 250000UL
#include <util/setbaud.h>

#define SAMPLE_RATE_HZ 1000UL
#define TIMER1_PRESCALE 64UL
#define AXIS_X 0
#define AXIS_Y 1
#define QUEUE_LEN 32u /* 32 ms of slack for the UART; a power of two */

#if (F_CPU / TIMER1_PRESCALE / SAMPLE_RATE_HZ) > 65536UL
#error "sample period does not fit Timer1"
#endif

typedef struct {
    uint16_t seq, x, y;
} sample_t;

static volatile sample_t queue[QUEUE_LEN];
static volatile uint8_t q_head, q_tail; /* ISR writes head, main reads tail */
static volatile uint16_t next_seq;
static volatile uint16_t x_counts;

static void uart_init(void)
{
    UBRR0H = UBRRH_VALUE;
    UBRR0L = UBRRL_VALUE;
#if USE_2X
    UCSR0A |= _BV(U2X0);
#else
    UCSR0A &= ~_BV(U2X0);
#endif
    UCSR0B = _BV(TXEN0);
    UCSR0C = _BV(UCSZ01) | _BV(UCSZ00); /* 8N1 */
}

static void uart_put(uint8_t byte)
{
    loop_until_bit_is_set(UCSR0A, UDRE0);
    UDR0 = byte;
}

static void adc_init(void)
{
    ADMUX = _BV(REFS0) | AXIS_X;                          /* AVcc reference */
    ADCSRB = _BV(ADTS2) | _BV(ADTS0);                      /* trigger: Timer1 compare B */
    ADCSRA = _BV(ADEN) | _BV(ADATE) | _BV(ADIE)
           | _BV(ADPS2) | _BV(ADPS1) | _BV(ADPS0);         /* 125 kHz ADC clock: 104 us each */
}

static void timer1_init(void)
{
    OCR1A = (uint16_t)(F_CPU / TIMER1_PRESCALE / SAMPLE_RATE_HZ - 1); /* CTC top: 1 kHz */
    OCR1B = 0;
    TCCR1A = 0;
    TCCR1B = _BV(WGM12) | _BV(CS11) | _BV(CS10);           /* CTC, clk/64 */
}

ISR(ADC_vect)
{
    uint16_t counts = ADC;
    if ((ADMUX & 0x0f) == AXIS_X) {
        x_counts = counts;
        ADMUX = _BV(REFS0) | AXIS_Y;
        ADCSRA |= _BV(ADSC);                               /* Y right after X */
        return;
    }
    ADMUX = _BV(REFS0) | AXIS_X;
    TIFR1 = _BV(OCF1B);            /* the next compare-B edge must be able to trigger again */
    uint16_t seq = next_seq++;
    uint8_t next = (uint8_t)((q_head + 1u) & (QUEUE_LEN - 1u));
    if (next == q_tail)
        return;                    /* full: dropped, the seq gap tells the host */
    queue[q_head].seq = seq;
    queue[q_head].x = x_counts;
    queue[q_head].y = counts;
    q_head = next;
}

int main(void)
{
    uint8_t cause = MCUSR; /* power-on, external, brown-out or watchdog reset */
    MCUSR = 0;
    uart_init();
    uart_put(0x00); /* end whatever partial frame the host saw during our reset */
    uint8_t boot[BOOT_WIRE_LEN];
    uint8_t n_boot = frame_encode_boot(cause, 0, boot);
    for (uint8_t i = 0; i < n_boot; i++)
        uart_put(boot[i]);
    adc_init();
    timer1_init();
    sei();
    uint8_t wire[FRAME_WIRE_LEN];
    for (;;) {
        if (q_tail == q_head)
            continue;
        sample_t s;
        ATOMIC_BLOCK(ATOMIC_RESTORESTATE)
        {
            s.seq = queue[q_tail].seq;
            s.x = queue[q_tail].x;
            s.y = queue[q_tail].y;
        }
        q_tail = (uint8_t)((q_tail + 1u) & (QUEUE_LEN - 1u));
        uint8_t n = frame_encode(s.seq, s.x, s.y, wire);
        for (uint8_t i = 0; i < n; i++)
            uart_put(wire[i]);
    }
}
