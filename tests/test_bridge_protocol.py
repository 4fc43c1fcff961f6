"""The wire protocol on bytes alone: COBS, CRC, framing, gaps, the decoder under any chunking."""
import binascii

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from snn_antenna.bridge.wire.protocol import (
    ENCODED_FRAME_LEN,
    REORDER_WINDOW,
    SEQ_MODULUS,
    CobsError,
    Decoder,
    Gap,
    Sample,
    cobs_decode,
    cobs_encode,
    crc16_xmodem,
    decode_all,
    encode_ascii,
    encode_binary,
    find_gaps,
    frame_payload,
)
from snn_antenna.core.errors import SpecError

# A board's stream: sequence numbers only move forward (with gaps, across the 16-bit wrap).
samples_st = st.builds(
    lambda start, steps, values: [((start + sum(steps[:i + 1])) % SEQ_MODULUS, x, y)
                                  for i, (x, y) in enumerate(values[:len(steps)])],
    st.integers(0, SEQ_MODULUS - 1), st.lists(st.integers(1, 40), min_size=60, max_size=60),
    st.lists(st.tuples(st.integers(0, 1023), st.integers(0, 1023)), min_size=1, max_size=60))


def feed_in_chunks(decoder, data, cuts):
    out, start = [], 0
    for cut in sorted(cuts) + [len(data)]:
        out += decoder.feed(data[start:cut])
        start = max(start, cut)
    return out + decoder.flush()


def test_crc_is_xmodem_check_value():
    # The published check value of CRC-16/XMODEM over "123456789".
    assert crc16_xmodem(b"123456789") == 0x31C3 == binascii.crc_hqx(b"123456789", 0)


def test_frame_layout_is_little_endian_payload_then_crc():
    raw = frame_payload(0x0102, 0x0304, 0x0005)
    assert raw[:6] == bytes([0x02, 0x01, 0x04, 0x03, 0x05, 0x00])
    assert int.from_bytes(raw[6:], "little") == crc16_xmodem(raw[:6])
    frame = encode_binary(0x0102, 0x0304, 0x0005)
    assert frame.endswith(b"\x00") and b"\x00" not in frame[:-1]
    assert len(frame) == ENCODED_FRAME_LEN + 1


@given(st.binary(max_size=600))
def test_cobs_round_trip_has_no_zeros(data):
    encoded = cobs_encode(data)
    assert 0 not in encoded
    assert cobs_decode(encoded) == data


def test_cobs_rejects_overrun_block():
    with pytest.raises(CobsError):
        cobs_decode(b"\x05\x01\x02")


def test_out_of_range_values_are_refused_by_the_encoder():
    with pytest.raises(SpecError, match="x = 1024"):
        encode_binary(0, 1024, 0)
    with pytest.raises(SpecError, match="seq"):
        encode_ascii(65536, 0, 0)


@settings(max_examples=150, deadline=None)
@given(samples_st, st.lists(st.integers(0, 800), max_size=30),
       st.sampled_from(["binary", "ascii"]))
def test_any_chunking_yields_exactly_the_frames(samples, cuts, wire_format):
    encode = encode_binary if wire_format == "binary" else encode_ascii
    data = b"".join(encode(*s) for s in samples)
    decoder = Decoder(wire_format, synced=True)
    got = feed_in_chunks(decoder, data, [c % (len(data) + 1) for c in cuts])
    assert got == [Sample(*s) for s in samples]
    expected_gaps = find_gaps([s[0] for s in samples])
    assert decoder.stats.gaps == len(expected_gaps) == len(decoder.gap_list)
    assert decoder.stats.lost_samples == sum(g.length for g in expected_gaps)
    assert decoder.stats.crc_errors == decoder.stats.framing_errors == 0


@settings(max_examples=150, deadline=None)
@given(st.integers(0, SEQ_MODULUS - 1), st.integers(1, 40),
       st.lists(st.tuples(st.integers(0, 39), st.binary(min_size=1, max_size=30)), max_size=8),
       st.lists(st.integers(0, 2000), max_size=20))
def test_garbage_between_frames_costs_exactly_one_framing_error_per_run(
        first_seq, n, garbage, cuts):
    """Garbage ended by a delimiter never eats a neighbouring frame; every zero-free run of it
    that cannot be a frame (a frame is 9 bytes) is one framing error."""
    frames = [encode_binary((first_seq + i) % SEQ_MODULUS, i % 1024, (7 * i) % 1024)
              for i in range(n)]
    expected_errors = 0
    inserts = {}
    for pos, junk in garbage:
        runs = [len(r) for r in junk.split(b"\x00")]
        if ENCODED_FRAME_LEN in runs:
            continue
        inserts.setdefault(pos % n, []).append(junk + b"\x00")
        expected_errors += sum(1 for r in runs if r)
    data = b"".join(b"".join(inserts.get(i, [])) + f for i, f in enumerate(frames))
    decoder = Decoder(synced=True)
    got = feed_in_chunks(decoder, data, [c % (len(data) + 1) for c in cuts])
    assert [s.seq for s in got] == [(first_seq + i) % SEQ_MODULUS for i in range(n)]
    assert decoder.stats.framing_errors == expected_errors
    assert decoder.stats.crc_errors == decoder.stats.range_errors == 0
    assert decoder.stats.gaps == 0


@settings(max_examples=200, deadline=None)
@given(st.binary(max_size=400), st.lists(st.integers(0, 400), max_size=15),
       st.sampled_from(["binary", "ascii"]))
def test_arbitrary_bytes_never_raise_and_chunking_does_not_matter(data, cuts, wire_format):
    whole = Decoder(wire_format, synced=True)
    expected = whole.feed(data) + whole.flush()
    chunked = Decoder(wire_format, synced=True)
    got = feed_in_chunks(chunked, data, [c % (len(data) + 1) for c in cuts])
    assert got == expected
    assert chunked.stats == whole.stats
    assert all(0 <= s.x <= 1023 and 0 <= s.y <= 1023 for s in got)


@given(st.integers(0, 7), st.integers(0, 7))
def test_every_single_bit_flip_in_a_frame_is_a_crc_error(byte, bit):
    raw = bytearray(frame_payload(4242, 1000, 17))
    raw[byte] ^= 1 << bit
    samples, decoder = decode_all(cobs_encode(bytes(raw)) + b"\x00")
    assert samples == [] and decoder.stats.crc_errors == 1


def test_gap_lengths_across_the_seq_wrap():
    seqs = [65533, 65534, 2, 3, 10]
    data = b"".join(encode_binary(s, 1, 2) for s in seqs)
    samples, decoder = decode_all(data)
    assert [s.seq for s in samples] == seqs
    assert decoder.gap_list == [Gap(1, 65534, 3), Gap(3, 3, 6)]
    assert (decoder.stats.gaps, decoder.stats.lost_samples) == (2, 9)
    assert find_gaps(seqs) == decoder.gap_list


def test_range_error_frame_is_skipped_and_leaves_a_gap():
    bad = cobs_encode(frame_payload(1, 1024, 5)) + b"\x00"
    samples, decoder = decode_all(encode_binary(0, 1, 1) + bad + encode_binary(2, 1, 1))
    assert [s.seq for s in samples] == [0, 2]
    assert (decoder.stats.range_errors, decoder.stats.gaps,
            decoder.stats.lost_samples) == (1, 1, 1)


def test_overlong_noise_is_one_framing_error_and_memory_stays_bounded():
    decoder = Decoder(synced=True)
    for _ in range(1000):
        decoder.feed(b"\x55" * 100)
    assert len(decoder._buffer) <= 64
    samples = decoder.feed(b"\x00" + encode_binary(9, 9, 9))
    assert samples == [Sample(9, 9, 9)] and decoder.stats.framing_errors == 1


def test_boot_noise_before_first_valid_frame_is_not_an_error():
    decoder = Decoder()                     # as after a port open: not yet synchronised
    frame = encode_binary(7, 1, 2)
    got = decoder.feed(b"\xf0\x01garbage" + frame[4:] + frame + encode_binary(8, 1, 2))
    assert [s.seq for s in got] == [7, 8]
    assert decoder.stats.framing_errors == 0 and decoder.stats.noise_bytes > 0
    decoder.resync()                        # a reconnect: half a frame, then frames again
    got = decoder.feed(frame[3:] + encode_binary(12, 1, 2)) + decoder.flush()
    assert [s.seq for s in got] == [12] and decoder.stats.framing_errors == 0
    assert decoder.gap_list == [Gap(1, 8, 3)]   # continuity survives the resync


def test_ascii_lines_accept_crlf_and_count_bad_lines():
    samples, decoder = decode_all(b"1,2,3\r\n2,4,5\n\nnonsense\n3,1024,1\n4,1,1\n", "ascii")
    assert samples == [Sample(1, 2, 3), Sample(2, 4, 5), Sample(4, 1, 1)]
    assert (decoder.stats.framing_errors, decoder.stats.range_errors) == (1, 1)
    assert decoder.stats.gaps == 1


def test_unknown_wire_format_names_the_choices():
    with pytest.raises(SpecError, match="format = 'hex'.*binary or ascii"):
        Decoder("hex")


# -- sequence discipline: duplicates, reorders, gaps, restarts ----------------------------------
def decode_seqs(seqs):
    decoder = Decoder(synced=True)
    got = decoder.feed(b"".join(encode_binary(s, s % 1024, 5) for s in seqs)) + decoder.flush()
    return [s.seq for s in got], decoder.stats


def test_a_duplicated_frame_is_dropped_and_counted_not_a_gap_of_65535():
    got, stats = decode_seqs([7, 8, 8, 9])
    assert got == [7, 8, 9]
    assert (stats.duplicates, stats.gaps, stats.lost_samples) == (1, 0, 0)


def test_a_swapped_pair_is_put_back_in_order_across_the_wrap():
    got, stats = decode_seqs([65534, 0, 65535, 1, 1, 2])
    assert got == [65534, 65535, 0, 1, 2]
    assert (stats.reordered, stats.duplicates, stats.gaps, stats.lost_samples) == (1, 1, 0, 0)


def test_a_hole_not_filled_within_the_window_is_one_gap_and_its_late_frame_is_dropped():
    seqs = [10, 11] + list(range(13, 13 + REORDER_WINDOW + 2)) + [12]
    got, stats = decode_seqs(seqs)
    assert got == [10, 11] + list(range(13, 13 + REORDER_WINDOW + 2))
    assert (stats.gaps, stats.lost_samples, stats.late, stats.reordered) == (1, 1, 1, 0)


def test_a_counter_restart_is_not_a_gap_of_almost_65536():
    got, stats = decode_seqs([500, 501, 0, 1, 2])
    assert got == [500, 501, 0, 1, 2]
    assert (stats.seq_restarts, stats.gaps, stats.lost_samples, stats.late) == (1, 0, 0, 0)


@settings(max_examples=150, deadline=None)
@given(st.integers(0, SEQ_MODULUS - 1), st.integers(30, 200),
       st.sets(st.integers(0, 199)), st.sets(st.integers(1, 199)), st.sets(st.integers(1, 198)))
def test_duplicates_and_swaps_deliver_the_clean_stream_with_every_fault_counted(
        start, n, dups, swaps, drops):
    """Whatever a misbehaving link repeats or swaps, what is delivered is the board's stream in
    order; each fault is counted once; and every frame received is accounted for. (The very
    first frame is never swapped: a receiver has nothing to order it against.)"""
    clean = [(start + i) % SEQ_MODULUS for i in range(n)]
    drops = {i for i in drops if 0 < i < n - 1}
    wire, i, n_swaps = [], 0, 0
    while i < n:
        if i in swaps and i + 1 < n and not {i, i + 1} & drops:
            wire += [clean[i + 1], clean[i]]
            n_swaps += 1
            i += 2
            continue
        if i not in drops:
            wire += [clean[i]] * (2 if i in dups else 1)
        i += 1
    got, stats = decode_seqs(wire)
    kept = [s for j, s in enumerate(clean) if j not in drops]
    assert got == kept
    assert stats.duplicates == len(wire) - len(set(wire))
    assert stats.lost_samples == len(drops) and stats.late == stats.seq_restarts == 0
    assert stats.reordered == n_swaps if not drops else stats.reordered <= n_swaps
    assert stats.frames + stats.duplicates + stats.late == len(wire)


@settings(max_examples=200, deadline=None)
@given(st.lists(st.integers(0, SEQ_MODULUS - 1), max_size=80))
def test_every_counter_is_bounded_by_what_was_received(seqs):
    got, stats = decode_seqs(seqs)
    assert stats.frames + stats.duplicates + stats.late == len(seqs) == len(got) + \
        stats.duplicates + stats.late
    assert stats.gaps <= len(seqs) and stats.reordered <= len(seqs)
    assert stats.seq_restarts <= len(seqs)
    assert stats.lost_samples <= len(seqs) * (SEQ_MODULUS // 2)
