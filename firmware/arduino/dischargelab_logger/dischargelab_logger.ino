/*
 * dischargelab_logger - battery discharge logger firmware for the Arduino Uno (ATmega328P).
 *
 * Samples up to six analog inputs at a host-set rate with hardware timing and
 * streams binary frames (protocol version 1, dlab_protocol.h) at 115200 baud:
 *
 *   A0  pack voltage through the divider + op-amp voltage follower (paper 3.1)
 *   A1  current sensor (ACS712 or shunt amplifier), optional
 *   A2  NTC thermistor divider, optional
 *   D7  load relay / MOSFET driver, HIGH = load connected (optional)
 *
 * Timing: Timer1 in CTC mode (prescaler 64, 4 us ticks) interrupts every
 * compare interval; a software postscaler makes periods up to 3600 s. Each
 * sample tick increments the 16-bit sample counter and starts an interrupt-driven
 * ADC conversion chain over the enabled channels (125 kHz ADC clock, 104 us per
 * conversion); finished samples go to an 8-entry ring that loop() turns into
 * frames. A sample that finds the ring full, or the ADC still busy, is dropped
 * but its counter value is used up, so the host sees the loss as a gap.
 *
 * Link budget (docs/acquisition.md): a SAMPLE frame is 9 + 2n bytes on the wire
 * (n channels). At 115200 baud (8N1, 11520 bytes/s): 1047 frames/s with one
 * channel, 886 with two, 768 with three.
 *
 * Host commands (all answered with ACK, IDENTIFY with INFO): IDENTIFY, SET_PERIOD
 * (u32 us), SET_CHANNELS (u8 mask), START (restarts the counter at 0 and takes the
 * first sample at once), STOP, SET_LOAD (u8). Bad frames are ignored.
 *
 * Build: Arduino IDE or arduino-cli, board "Arduino Uno"; no libraries needed.
 */

#include <Arduino.h>
#include <avr/interrupt.h>
#include <stdlib.h>
#include <string.h>

#include "dlab_protocol.h"

#define FW_NAME "dischargelab-logger"
#define FW_VERSION "1.0.0"
#define BAUDRATE 115200UL
#define LOAD_PIN 7
#define RING_SIZE 8
#define RX_MAX 40
#define DEFAULT_PERIOD_US 1000000UL

struct SampleEntry {
    uint16_t seq;
    uint8_t mask;
    uint16_t codes[DLAB_MAX_CHANNELS];
};

/* --- state shared with the interrupt handlers ---------------------------------- */
static volatile uint8_t g_mask = 1;            /* channels being sampled (bit k = Ak) */
static volatile uint16_t g_postscale = 1;      /* compare intervals per sample */
static volatile uint16_t g_postcount = 0;
static volatile uint16_t g_seq = 0;            /* next sample counter value */
static volatile bool g_streaming = false;
static volatile bool g_adc_busy = false;
static volatile uint8_t g_conv_channels[DLAB_MAX_CHANNELS];
static volatile uint8_t g_conv_count = 0;
static volatile uint8_t g_conv_index = 0;
static volatile SampleEntry g_conv;            /* sample being converted */
static volatile SampleEntry g_ring[RING_SIZE];
static volatile uint8_t g_head = 0;            /* written by the ADC interrupt */
static volatile uint8_t g_tail = 0;            /* read by loop() */

/* --- state of the main loop ------------------------------------------------------- */
static uint32_t g_period_us = DEFAULT_PERIOD_US;
static bool g_load_on = false;
static uint8_t g_rx[RX_MAX];
static uint8_t g_rx_len = 0;
static bool g_rx_overflow = false;
static uint8_t g_tx[DLAB_MAX_FRAME + 4];

static inline void adc_start(uint8_t channel)
{
    ADMUX = _BV(REFS0) | (channel & 0x07); /* AVcc (5 V) reference, right adjusted */
    ADCSRA |= _BV(ADSC);
}

/* Called with interrupts disabled (timer interrupt, or START inside cli()). */
static void take_sample(void)
{
    uint16_t seq = g_seq++;
    if (g_adc_busy)
        return; /* previous chain still converting: this sample is lost (gap) */
    uint8_t mask = g_mask, n = 0;
    for (uint8_t ch = 0; ch < DLAB_MAX_CHANNELS; ch++)
        if (mask & (1 << ch))
            g_conv_channels[n++] = ch;
    g_conv.seq = seq;
    g_conv.mask = mask;
    g_conv_count = n;
    g_conv_index = 0;
    g_adc_busy = true;
    adc_start(g_conv_channels[0]);
}

ISR(TIMER1_COMPA_vect)
{
    if (++g_postcount < g_postscale)
        return;
    g_postcount = 0;
    take_sample();
}

ISR(ADC_vect)
{
    g_conv.codes[g_conv_index++] = ADC;
    if (g_conv_index < g_conv_count) {
        adc_start(g_conv_channels[g_conv_index]);
        return;
    }
    g_adc_busy = false;
    uint8_t next = (uint8_t)((g_head + 1) % RING_SIZE);
    if (next == g_tail)
        return; /* ring full (link too slow): sample dropped, the host sees the gap */
    volatile SampleEntry *e = &g_ring[g_head];
    e->seq = g_conv.seq;
    e->mask = g_conv.mask;
    for (uint8_t k = 0; k < g_conv_count; k++)
        e->codes[k] = g_conv.codes[k];
    g_head = next;
}

/* --- timer ------------------------------------------------------------------------ */
static void timer_setup(void)
{
    TCCR1A = 0;
    TCCR1B = _BV(WGM12) | _BV(CS11) | _BV(CS10); /* CTC on OCR1A, clk/64 = 4 us ticks */
    TIMSK1 = 0;
}

static bool timer_set_period(uint32_t requested_us)
{
    uint16_t postscale;
    uint32_t ticks;
    uint32_t applied = dlab_quantize_period(requested_us, &postscale, &ticks);
    if (applied == 0)
        return false;
    uint8_t sreg = SREG;
    cli();
    g_postscale = postscale;
    g_postcount = 0;
    OCR1A = (uint16_t)(ticks - 1);
    TCNT1 = 0;
    SREG = sreg;
    g_period_us = applied;
    return true;
}

/* --- output ----------------------------------------------------------------------- */
static void send_frame(size_t len)
{
    Serial.write(g_tx, len); /* blocks only if the 64-byte TX buffer is full */
}

static void send_ack(uint8_t command, uint8_t status, uint32_t value)
{
    send_frame(dlab_ack_frame(command, status, value, g_tx));
}

static char *append(char *p, const char *text)
{
    while (*text)
        *p++ = *text++;
    return p;
}

static char *append_number(char *p, const char *key, uint32_t value)
{
    char digits[11];
    p = append(p, key);
    ultoa(value, digits, 10);
    return append(p, digits);
}

static void send_info(void)
{
    char text[DLAB_MAX_FRAME];
    char *p = text;
    p = append(p, "fw=" FW_NAME ";fw_version=" FW_VERSION);
    p = append_number(p, ";proto=", DLAB_PROTOCOL_VERSION);
    p = append(p, ";board=uno;adc_bits=10;vref_mV=5000");
    p = append_number(p, ";channels=", DLAB_MAX_CHANNELS);
    p = append_number(p, ";period_us=", g_period_us);
    p = append_number(p, ";mask=", g_mask);
    p = append_number(p, ";streaming=", g_streaming ? 1 : 0);
    p = append_number(p, ";load=", g_load_on ? 1 : 0);
    send_frame(dlab_seal(DLAB_INFO, (const uint8_t *)text, (size_t)(p - text), g_tx));
}

static void stream_start(void)
{
    cli();
    g_seq = 0;
    g_postcount = 0;
    g_head = g_tail = 0;
    g_adc_busy = false;
    TCNT1 = 0;
    TIFR1 = _BV(OCF1A);
    g_streaming = true;
    TIMSK1 = _BV(OCIE1A);
    take_sample(); /* sample 0 at the START instant */
    sei();
}

static void stream_stop(void)
{
    cli();
    TIMSK1 = 0;
    g_streaming = false;
    sei();
}

static void set_load(bool on)
{
    g_load_on = on;
    digitalWrite(LOAD_PIN, on ? HIGH : LOW);
}

/* --- commands ---------------------------------------------------------------------- */
static void handle_command(uint8_t type, uint32_t arg)
{
    switch (type) {
    case DLAB_IDENTIFY:
        send_info();
        break;
    case DLAB_SET_PERIOD:
        if (timer_set_period(arg))
            send_ack(type, DLAB_OK, g_period_us);
        else
            send_ack(type, DLAB_BAD_ARGUMENT, g_period_us);
        break;
    case DLAB_SET_CHANNELS:
        if (arg > 0 && arg < (1UL << DLAB_MAX_CHANNELS)) {
            cli();
            g_mask = (uint8_t)arg;
            sei();
            DIDR0 = (uint8_t)arg; /* analog-only pins: disable their digital input buffers */
            send_ack(type, DLAB_OK, arg);
        } else {
            send_ack(type, DLAB_BAD_ARGUMENT, g_mask);
        }
        break;
    case DLAB_START:
        send_ack(type, DLAB_OK, 0); /* the ACK leaves before sample 0 */
        stream_start();
        break;
    case DLAB_STOP:
        stream_stop();
        send_ack(type, DLAB_OK, 0);
        break;
    case DLAB_SET_LOAD:
        set_load(arg != 0);
        send_ack(type, DLAB_OK, g_load_on ? 1 : 0);
        break;
    }
}

static void read_commands(void)
{
    while (Serial.available() > 0) {
        uint8_t b = (uint8_t)Serial.read();
        if (b != 0) {
            if (g_rx_len < RX_MAX)
                g_rx[g_rx_len++] = b;
            else
                g_rx_overflow = true; /* too long for a command: drop it at the delimiter */
            continue;
        }
        if (g_rx_len > 0 && !g_rx_overflow) {
            uint8_t type;
            uint32_t arg;
            if (dlab_parse_command(g_rx, g_rx_len, &type, &arg) == 1)
                handle_command(type, arg);
        }
        g_rx_len = 0;
        g_rx_overflow = false;
    }
}

/* --- Arduino entry points ------------------------------------------------------------ */
void setup(void)
{
    pinMode(LOAD_PIN, OUTPUT);
    set_load(false); /* load disconnected at power-up */
    Serial.begin(BAUDRATE);
    ADCSRA = _BV(ADEN) | _BV(ADIE) | _BV(ADPS2) | _BV(ADPS1) | _BV(ADPS0); /* 16 MHz / 128 */
    DIDR0 = g_mask;
    timer_setup();
    timer_set_period(DEFAULT_PERIOD_US);
}

void loop(void)
{
    read_commands();
    if (g_tail == g_head)
        return;
    volatile SampleEntry *e = &g_ring[g_tail];
    uint8_t n = dlab_popcount(e->mask);
    if (Serial.availableForWrite() < 9 + 2 * n)
        return; /* wait for room rather than block; the ring absorbs the wait */
    uint16_t codes[DLAB_MAX_CHANNELS];
    for (uint8_t k = 0; k < n; k++)
        codes[k] = e->codes[k];
    send_frame(dlab_sample_frame(e->seq, e->mask, codes, g_tx));
    g_tail = (uint8_t)((g_tail + 1) % RING_SIZE);
}
