/*
 * dlab_protocol.h - wire format of the dischargelab logger (protocol version 1).
 *
 * Plain C99 with no Arduino dependency, so the same code is compiled into the
 * sketch and into a host-side test that checks it byte for byte against the
 * Python implementation (src/dischargelab/acquire/protocol.py).
 *
 * Frame on the wire:  COBS( version | type | payload | crc16_lo | crc16_hi ) 0x00
 *   crc16 = CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF, no reflection, no xorout)
 *           over version, type and payload; check value 0x29B1 for "123456789".
 *   COBS  = Consistent Overhead Byte Stuffing (Cheshire & Baker, IEEE/ACM ToN 1999):
 *           no 0x00 inside a frame, so 0x00 delimits frames and resynchronises.
 * Multi-byte integers are little-endian. See docs/acquisition.md for the tables.
 */
#ifndef DLAB_PROTOCOL_H
#define DLAB_PROTOCOL_H

#include <stddef.h>
#include <stdint.h>

#define DLAB_PROTOCOL_VERSION 1
#define DLAB_MAX_CHANNELS 6
#define DLAB_MAX_FRAME 200 /* decoded bytes: version + type + payload + crc */
#define DLAB_ADC_MAX 1023

/* frame types */
#define DLAB_SAMPLE 0x01
#define DLAB_INFO 0x02
#define DLAB_ACK 0x03
#define DLAB_IDENTIFY 0x10
#define DLAB_SET_PERIOD 0x11
#define DLAB_SET_CHANNELS 0x12
#define DLAB_START 0x13
#define DLAB_STOP 0x14
#define DLAB_SET_LOAD 0x15

/* ACK status */
#define DLAB_OK 0
#define DLAB_BAD_ARGUMENT 1

/* Timer1: prescaler 64 at 16 MHz = 4 us per tick, 16-bit compare */
#define DLAB_TICK_US 4UL
#define DLAB_MAX_TICKS 65536UL
#define DLAB_MIN_PERIOD_US 500UL
#define DLAB_MAX_PERIOD_US 3600000000UL

static uint16_t dlab_crc16(const uint8_t *data, size_t n)
{
    uint16_t crc = 0xFFFF;
    for (size_t i = 0; i < n; i++) {
        crc ^= (uint16_t)data[i] << 8;
        for (uint8_t bit = 0; bit < 8; bit++)
            crc = (crc & 0x8000) ? (uint16_t)((crc << 1) ^ 0x1021) : (uint16_t)(crc << 1);
    }
    return crc;
}

/* COBS-encode n bytes; returns the encoded length (no delimiter). out needs n + n/254 + 1. */
static size_t dlab_cobs_encode(const uint8_t *in, size_t n, uint8_t *out)
{
    size_t code_pos = 0, o = 1;
    uint8_t code = 1;
    for (size_t i = 0; i < n; i++) {
        if (in[i] == 0) {
            out[code_pos] = code;
            code_pos = o++;
            code = 1;
        } else {
            out[o++] = in[i];
            if (++code == 0xFF) {
                out[code_pos] = code;
                code_pos = o++;
                code = 1;
            }
        }
    }
    out[code_pos] = code;
    return o;
}

/* COBS-decode; returns the decoded length, or 0 if the input is not valid COBS. */
static size_t dlab_cobs_decode(const uint8_t *in, size_t n, uint8_t *out, size_t out_max)
{
    size_t i = 0, o = 0;
    while (i < n) {
        uint8_t code = in[i];
        if (code == 0 || i + code > n)
            return 0;
        for (uint8_t k = 1; k < code; k++) {
            if (in[i + k] == 0 || o >= out_max)
                return 0;
            out[o++] = in[i + k];
        }
        i += code;
        if (code != 0xFF && i < n) {
            if (o >= out_max)
                return 0;
            out[o++] = 0;
        }
    }
    return o;
}

/* Build a complete wire frame (COBS + delimiter) into out; returns its length (0 if too long). */
static size_t dlab_seal(uint8_t type, const uint8_t *payload, size_t n, uint8_t *out)
{
    uint8_t raw[DLAB_MAX_FRAME];
    if (n + 4 > DLAB_MAX_FRAME)
        return 0;
    raw[0] = DLAB_PROTOCOL_VERSION;
    raw[1] = type;
    for (size_t i = 0; i < n; i++)
        raw[2 + i] = payload[i];
    uint16_t crc = dlab_crc16(raw, n + 2);
    raw[n + 2] = (uint8_t)(crc & 0xFF);
    raw[n + 3] = (uint8_t)(crc >> 8);
    size_t len = dlab_cobs_encode(raw, n + 4, out);
    out[len++] = 0;
    return len;
}

static uint8_t dlab_popcount(uint8_t mask)
{
    uint8_t n = 0;
    for (; mask; mask >>= 1)
        n += mask & 1;
    return n;
}

/* SAMPLE frame: seq u16, mask u8, one u16 code per set bit (lowest channel first). */
static size_t dlab_sample_frame(uint16_t seq, uint8_t mask, const uint16_t *codes, uint8_t *out)
{
    uint8_t payload[3 + 2 * DLAB_MAX_CHANNELS];
    uint8_t n = dlab_popcount(mask);
    payload[0] = (uint8_t)(seq & 0xFF);
    payload[1] = (uint8_t)(seq >> 8);
    payload[2] = mask;
    for (uint8_t k = 0; k < n; k++) {
        payload[3 + 2 * k] = (uint8_t)(codes[k] & 0xFF);
        payload[4 + 2 * k] = (uint8_t)(codes[k] >> 8);
    }
    return dlab_seal(DLAB_SAMPLE, payload, 3 + 2 * (size_t)n, out);
}

/* ACK frame: command u8, status u8, value u32. */
static size_t dlab_ack_frame(uint8_t command, uint8_t status, uint32_t value, uint8_t *out)
{
    uint8_t payload[6] = {command, status, (uint8_t)value, (uint8_t)(value >> 8),
                          (uint8_t)(value >> 16), (uint8_t)(value >> 24)};
    return dlab_seal(DLAB_ACK, payload, 6, out);
}

/*
 * Sample period the timer can make for a requested one [us]: n = ceil(P / 262144)
 * compare intervals (software postscaler) of ticks = round(P / (4 n)) 4-us ticks.
 * Returns the applied period, or 0 if P is outside 500 us .. 3600 s.
 */
static uint32_t dlab_quantize_period(uint32_t p, uint16_t *postscale, uint32_t *ticks)
{
    if (p < DLAB_MIN_PERIOD_US || p > DLAB_MAX_PERIOD_US)
        return 0;
    const uint32_t span = DLAB_TICK_US * DLAB_MAX_TICKS;
    uint32_t n = (p + span - 1) / span;
    uint32_t t = (p + 2 * n) / (DLAB_TICK_US * n);
    if (t < 1)
        t = 1;
    if (t > DLAB_MAX_TICKS)
        t = DLAB_MAX_TICKS;
    *postscale = (uint16_t)n;
    *ticks = t;
    return n * t * DLAB_TICK_US;
}

/*
 * Check and unpack a host command (COBS bytes without the delimiter).
 * Returns 1 with *type and *arg set; 0 for anything else (corrupt, unknown type, wrong
 * length), which the firmware ignores exactly like the Python decoder rejects it.
 */
static int dlab_parse_command(const uint8_t *enc, size_t n, uint8_t *type, uint32_t *arg)
{
    uint8_t raw[DLAB_MAX_FRAME];
    size_t len = dlab_cobs_decode(enc, n, raw, sizeof raw);
    if (len < 4)
        return 0;
    uint16_t crc = (uint16_t)raw[len - 2] | ((uint16_t)raw[len - 1] << 8);
    if (dlab_crc16(raw, len - 2) != crc || raw[0] != DLAB_PROTOCOL_VERSION)
        return 0;
    size_t plen = len - 4;
    const uint8_t *p = raw + 2;
    *type = raw[1];
    *arg = 0;
    switch (raw[1]) {
    case DLAB_SET_PERIOD:
        if (plen != 4)
            return 0;
        *arg = (uint32_t)p[0] | ((uint32_t)p[1] << 8) | ((uint32_t)p[2] << 16) |
               ((uint32_t)p[3] << 24);
        return 1;
    case DLAB_SET_CHANNELS:
    case DLAB_SET_LOAD:
        if (plen != 1)
            return 0;
        *arg = p[0];
        return 1;
    case DLAB_IDENTIFY:
    case DLAB_START:
    case DLAB_STOP:
        return plen == 0 ? 1 : 0;
    default:
        return 0;
    }
}

#endif /* DLAB_PROTOCOL_H */
