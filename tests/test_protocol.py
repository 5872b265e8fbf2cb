"""Wire protocol of the Arduino logger: pure encode/parse, property-tested."""

import shutil
import subprocess
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from dischargelab.acquire import protocol as proto

REPO = Path(__file__).resolve().parents[1]
FIRMWARE = REPO / "firmware" / "arduino" / "dischargelab_logger"

masks = st.integers(1, (1 << proto.MAX_CHANNELS) - 1)


@st.composite
def sample_frames(draw):
    mask = draw(masks)
    n = bin(mask).count("1")
    codes = tuple(draw(st.lists(st.integers(0, proto.ADC_MAX_CODE), min_size=n, max_size=n)))
    return proto.SampleFrame(draw(st.integers(0, 0xFFFF)), mask, codes)


def wire(frame: proto.SampleFrame) -> bytes:
    return proto.encode_sample(frame.seq, frame.mask, frame.codes)


def feed_in_chunks(parser, data: bytes, cuts) -> list:
    """Feed ``data`` split at the (sorted) cut positions."""
    frames, start = [], 0
    for cut in sorted({c % (len(data) + 1) for c in cuts}) + [len(data)]:
        frames += parser.feed(data[start:cut])
        start = cut
    return frames


def is_ordered_subsequence(got, sent) -> bool:
    it = iter(sent)
    return all(any(g == s for s in it) for g in got)


# ---------------------------------------------------------------------------- primitives

def test_crc16_is_ccitt_false():
    assert proto.crc16(b"123456789") == 0x29B1


@given(st.binary(max_size=700))
def test_cobs_round_trip_and_no_zero_inside(data):
    encoded = proto.cobs_encode(data)
    assert 0 not in encoded
    assert proto.cobs_decode(encoded) == data
    assert len(encoded) <= len(data) + len(data) // 254 + 1


def test_frame_sizes_and_link_budget():
    # 9 + 2n bytes; at 115200 baud (11520 B/s): 1047 / 886 / 768 frames per second
    assert [proto.sample_frame_bytes(n) for n in (1, 2, 3, 6)] == [11, 13, 15, 21]
    assert proto.max_frame_rate_Hz(1) == pytest.approx(11520 / 11)
    assert int(proto.max_frame_rate_Hz(3)) == 768


@given(st.integers(proto.MIN_PERIOD_US, proto.MAX_PERIOD_US))
def test_period_quantisation_is_close(period_us):
    applied = proto.quantize_period_us(period_us)
    span = proto.TIMER_TICK_US * proto.TIMER_MAX_TICKS
    n = -(-period_us // span)
    assert applied % (proto.TIMER_TICK_US * n) == 0
    assert abs(applied - period_us) <= 2 * n          # half a tick per compare interval


def test_period_out_of_range():
    with pytest.raises(ValueError):
        proto.quantize_period_us(proto.MIN_PERIOD_US - 1)
    with pytest.raises(ValueError):
        proto.quantize_period_us(proto.MAX_PERIOD_US + 1)


# ---------------------------------------------------------------------------- round trips

@given(st.lists(sample_frames(), min_size=1, max_size=30), st.lists(st.integers(0, 10**6)))
def test_round_trip_in_arbitrary_chunks(frames, cuts):
    parser = proto.FrameParser(synced=True)
    got = feed_in_chunks(parser, b"".join(wire(f) for f in frames), cuts)
    assert got == frames
    assert parser.frames_corrupt == 0


@given(st.sampled_from([c for c in proto.MessageType if c in proto.COMMAND_TYPES]),
       st.integers(0, 255), st.integers(0, 2**32 - 1))
def test_commands_info_and_ack_round_trip(command, small, big):
    arg = big if command == proto.MessageType.SET_PERIOD else small
    parser = proto.FrameParser(synced=True)
    (cmd,) = parser.feed(proto.encode_command(command, arg))
    assert cmd.command == command
    if cmd.payload:
        assert int.from_bytes(cmd.payload, "little") == arg
    (ack,) = parser.feed(proto.encode_ack(command, proto.AckStatus.OK, big))
    assert ack == proto.AckFrame(command, 0, big)
    (info,) = parser.feed(proto.encode_info({"fw": "x", "period_us": big}))
    assert info.fields == {"fw": "x", "period_us": str(big)}


def test_parser_skips_a_frame_cut_at_connection_time():
    frames = [proto.SampleFrame(k, 1, (k,)) for k in range(5)]
    data = b"".join(wire(f) for f in frames)
    parser = proto.FrameParser()                      # not synced: starts mid-stream
    got = parser.feed(data[4:])
    assert got == frames[1:]
    # the skipped bytes do not count the delimiter
    assert parser.frames_corrupt == 0 and parser.bytes_skipped == len(wire(frames[0])) - 4 - 1


# ---------------------------------------------------------------------------- faults

@settings(max_examples=200)
@given(st.lists(st.tuples(sample_frames(), st.binary(max_size=40)), min_size=1, max_size=20),
       st.lists(st.integers(0, 10**6)))
def test_garbage_never_crashes_nor_yields_a_wrong_sample(items, cuts):
    parser = proto.FrameParser(synced=True)
    stream, sent, clean = b"", [], []
    for frame, garbage in items:
        stream += garbage
        clean.append(not garbage or garbage.endswith(b"\x00"))
        stream += wire(frame)
        sent.append(frame)
    got = [f for f in feed_in_chunks(parser, stream, cuts) if isinstance(f, proto.SampleFrame)]
    assert is_ordered_subsequence(got, sent)
    # every frame that garbage did not run into arrives
    assert [f for f, ok in zip(sent, clean) if ok] == [f for f in got if f in
                                                       [s for s, ok in zip(sent, clean) if ok]]
    if not all(clean):
        assert parser.frames_corrupt >= 1


@settings(max_examples=300)
@given(st.lists(sample_frames(), min_size=1, max_size=12), st.data())
def test_bit_flips_are_always_detected(frames, data):
    """1-3 flipped bits per frame (CRC-16/CCITT: Hamming distance 4): never accepted."""
    stream, damaged = b"", []
    for frame in frames:
        raw = bytearray(wire(frame))
        flip = data.draw(st.booleans())
        if flip:
            bits = data.draw(st.lists(st.integers(0, len(raw) * 8 - 1), min_size=1, max_size=3,
                                      unique=True))
            for b in bits:
                raw[b // 8] ^= 1 << (b % 8)
        damaged.append(flip)
        stream += bytes(raw)
    parser = proto.FrameParser(synced=True)
    got = parser.feed(stream + b"\x00")          # the next frame's delimiter ends the last
    intact = [f for f, d in zip(frames, damaged) if not d]
    assert all(isinstance(f, proto.SampleFrame) for f in got)
    assert is_ordered_subsequence(got, intact)
    if any(damaged):
        assert parser.frames_corrupt >= 1
    # a frame is only lost if it or its predecessor (delimiter) was hit
    for k, frame in enumerate(frames):
        if not damaged[k] and (k == 0 or not damaged[k - 1]):
            assert frame in got


@settings(max_examples=300)
@given(st.lists(sample_frames(), min_size=1, max_size=12), st.data())
def test_single_dropped_byte_is_always_detected(frames, data):
    """A sample frame decodes to 7 + 2n bytes (odd); one lost byte makes it even."""
    stream, damaged = b"", []
    for frame in frames:
        raw = wire(frame)
        drop = data.draw(st.booleans())
        if drop:
            k = data.draw(st.integers(0, len(raw) - 1))
            raw = raw[:k] + raw[k + 1:]
        damaged.append(drop)
        stream += raw
    parser = proto.FrameParser(synced=True)
    got = parser.feed(stream)
    assert is_ordered_subsequence(got, [f for f, d in zip(frames, damaged) if not d])


@settings(max_examples=200)
@given(st.lists(sample_frames(), min_size=2, max_size=20), st.data())
def test_random_drops_never_yield_a_wrong_sample(frames, data):
    stream = b"".join(wire(f) for f in frames)
    drops = set(data.draw(st.lists(st.integers(0, len(stream) - 1), max_size=12)))
    damaged_stream = bytes(b for i, b in enumerate(stream) if i not in drops)
    parser = proto.FrameParser(synced=True)
    got = parser.feed(damaged_stream)
    assert is_ordered_subsequence(got, frames)
    assert len(got) + parser.frames_corrupt <= len(frames)


@given(st.binary(max_size=3000))
def test_pure_garbage_is_harmless(garbage):
    parser = proto.FrameParser()
    for k in range(0, len(garbage), 97):
        parser.feed(garbage[k:k + 97])
    # nothing to assert beyond "no exception": valid frames in garbage need a CRC match
    assert parser.frames_ok + parser.frames_corrupt >= 0


# ---------------------------------------------------------------------------- sequence counter

@given(st.integers(0, 0xFFFF), st.lists(st.integers(1, 30000), max_size=60))
def test_sequence_gaps_counted_across_wraps(start, steps):
    tracker = proto.SequenceTracker()
    index = start
    assert tracker.update(index & 0xFFFF) == start
    for step in steps:
        index += step
        assert tracker.update(index & 0xFFFF) == index
    assert tracker.lost == sum(s - 1 for s in steps)


def test_sequence_gap_longer_than_the_counter_uses_the_clock():
    tracker = proto.SequenceTracker()
    tracker.update(10)
    # 70000 samples later (one wrap + 4464): the counter alone would say 4464
    assert tracker.update((10 + 70000) & 0xFFFF, expected_step=70010) == 70010
    assert tracker.lost == 69999


def test_restart_counts_samples_missed_before_the_first():
    tracker = proto.SequenceTracker()
    tracker.restart(first_seq=0)
    assert tracker.update(6) == 6
    assert tracker.lost == 6


# ---------------------------------------------------------------------------- firmware code

HARNESS = r"""
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include "dlab_protocol.h"
static void hex(const uint8_t *b, size_t n) {
    for (size_t i = 0; i < n; i++) printf("%02x", b[i]);
    printf("\n");
}
int main(void) {
    char kind[16];
    uint8_t out[256];
    while (scanf("%15s", kind) == 1) {
        if (!strcmp(kind, "sample")) {
            unsigned seq, mask, n; uint16_t codes[6];
            scanf("%u %u %u", &seq, &mask, &n);
            for (unsigned k = 0; k < n; k++) {
                unsigned c; scanf("%u", &c); codes[k] = (uint16_t)c;
            }
            hex(out, dlab_sample_frame((uint16_t)seq, (uint8_t)mask, codes, out));
        } else if (!strcmp(kind, "ack")) {
            unsigned cmd, status; unsigned long value;
            scanf("%u %u %lu", &cmd, &status, &value);
            hex(out, dlab_ack_frame((uint8_t)cmd, (uint8_t)status, (uint32_t)value, out));
        } else if (!strcmp(kind, "period")) {
            unsigned long p; uint16_t post; uint32_t ticks;
            scanf("%lu", &p);
            printf("%lu\n", (unsigned long)dlab_quantize_period((uint32_t)p, &post, &ticks));
        } else if (!strcmp(kind, "command")) {
            char text[128]; uint8_t enc[64]; size_t n = 0; uint8_t type; uint32_t arg;
            scanf("%127s", text);
            for (size_t i = 0; text[2 * i]; i++) {
                unsigned v; sscanf(text + 2 * i, "%2x", &v); enc[n++] = (uint8_t)v;
            }
            int ok = dlab_parse_command(enc, n - 1, &type, &arg);   /* without the delimiter */
            printf("%d %u %lu\n", ok, ok ? type : 0, ok ? (unsigned long)arg : 0UL);
        }
    }
    return 0;
}
"""


@pytest.fixture(scope="module")
def firmware_harness(tmp_path_factory):
    compiler = shutil.which("cc") or shutil.which("gcc") or shutil.which("clang")
    if compiler is None:
        pytest.skip("no C compiler to build the firmware's protocol code")
    work = tmp_path_factory.mktemp("fw")
    (work / "harness.c").write_text(HARNESS)
    exe = work / "harness"
    subprocess.run([compiler, "-std=c99", "-Wall", "-Werror", "-I", str(FIRMWARE),
                    str(work / "harness.c"), "-o", str(exe)], check=True)
    return exe


@settings(max_examples=60)
@given(st.lists(sample_frames(), min_size=1, max_size=40),
       st.lists(st.integers(proto.MIN_PERIOD_US - 10, proto.MAX_PERIOD_US + 10), max_size=20),
       st.lists(st.tuples(st.sampled_from(sorted(proto.COMMAND_TYPES)), st.integers(0, 255),
                          st.integers(0, 2**32 - 1), st.booleans()), max_size=10))
def test_firmware_protocol_code_matches_python(firmware_harness, frames, periods, commands):
    """The sketch's dlab_protocol.h, compiled for the host, produces the same bytes."""
    lines, expected = [], []
    for f in frames:
        lines.append(f"sample {f.seq} {f.mask} {len(f.codes)} " + " ".join(map(str, f.codes)))
        expected.append(wire(f).hex())
        lines.append(f"ack {f.mask} {f.seq & 1} {f.seq * 65537}")
        expected.append(proto.encode_ack(f.mask, f.seq & 1, f.seq * 65537).hex())
    for p in periods:
        lines.append(f"period {p}")
        try:
            expected.append(str(proto.quantize_period_us(p)))
        except ValueError:
            expected.append("0")
    for cmd, small, big, corrupt in commands:
        arg = big if cmd == proto.MessageType.SET_PERIOD else small
        raw = bytearray(proto.encode_command(cmd, arg))
        if corrupt:
            raw[1 if len(raw) > 2 else 0] ^= 0x40
        lines.append(f"command {raw.hex()}")
        decoded = [f for f in proto.FrameParser(synced=True).feed(bytes(raw))
                   if isinstance(f, proto.CommandFrame)]
        if decoded:
            payload = decoded[0].payload
            expected.append(f"1 {decoded[0].command} {int.from_bytes(payload, 'little')}")
        else:
            expected.append("0 0 0")
    result = subprocess.run([str(firmware_harness)], input="\n".join(lines) + "\n",
                            capture_output=True, text=True, check=True)
    assert result.stdout.split("\n")[:-1] == expected
