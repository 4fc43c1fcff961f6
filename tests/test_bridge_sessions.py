"""Board sessions: a board that restarts its count (a reset, a power cycle, a port reopened by
DTR) is counted as a restart, never as lost samples or duplicates, wherever in its count the
restart falls, together with wraps of the 16-bit count, duplicates, swaps, drops and host
stalls. Every counter reconciles, per session, with what the board sent:
frames + lost = sent."""
import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from snn_antenna.bridge.wire.protocol import (
    CLOCK_TOLERANCE,
    HALF_MODULUS,
    REORDER_WINDOW,
    RESTART_SILENCE_S,
    RESTART_SLACK_S,
    SEQ_MODULUS,
    Decoder,
    decode_all,
    encode_binary,
    encode_boot,
)

RATE = 1000.0
CLEAN = REORDER_WINDOW + 2          # frames at each end of a session that carry no fault


@st.composite
def board_runs(draw, max_sessions=4, max_len=1500):
    """A board's life: sessions (first seq, length, the silence before it, its faults) and the
    host's stalls. The first session may start anywhere in the count, so that wraps happen."""
    sessions = []
    for i in range(draw(st.integers(1, max_sessions))):
        n = draw(st.integers(2 * CLEAN + 2, max_len))
        first = draw(st.integers(0, SEQ_MODULUS - 1)) if i == 0 else draw(
            st.one_of(st.just(0), st.integers(0, SEQ_MODULUS - 1)))
        inner = st.integers(CLEAN, n - CLEAN - 2)
        sessions.append({
            "first": first, "n": n,
            "silence_s": draw(st.sampled_from([0.0, 0.02, 0.2, 1.5])) if i else 0.0,
            "drops": draw(st.sets(inner, max_size=4)), "dups": draw(st.sets(inner, max_size=4)),
            "swaps": draw(st.sets(inner, max_size=3)),
        })
    stalls = draw(st.lists(st.tuples(st.floats(0, 1), st.sampled_from([0.3, 2.0, 7.0])),
                           max_size=2))
    chunk = draw(st.integers(1, 40))
    return sessions, stalls, chunk


def wire_of(sessions, boot_frames: bool):
    """What the board sends, as atomic writes (bytes, board time, session, sent in order)."""
    writes, t = [], 0.0
    for s_index, s in enumerate(sessions):
        t += s["silence_s"]
        if boot_frames:
            writes.append((encode_boot("binary", s["first"]), t, s_index, []))
        seqs = [(s["first"] + k) % SEQ_MODULUS for k in range(s["n"])]
        k = 0
        while k < s["n"]:
            at = t + k / RATE
            if k in s["swaps"] and not {k, k + 1} & (s["drops"] | s["dups"]):
                writes.append((encode_binary(seqs[k + 1], 1, 1) + encode_binary(seqs[k], 1, 1),
                               at + 1 / RATE, s_index, [seqs[k], seqs[k + 1]]))
                k += 2
                continue
            if k in s["drops"]:
                k += 1
                continue
            copies = 2 if k in s["dups"] else 1
            writes.append((encode_binary(seqs[k], 1, 1) * copies, at, s_index, [seqs[k]]))
            k += 1
        t += s["n"] / RATE
    return writes


def host_feed(writes, stalls, chunk):
    """The host reads up to ``chunk`` whole writes at a time, never across a pause of the board
    (its read loop takes what waits within milliseconds); a stall holds its reads back, then it
    reads the backlog at once (its clock runs on, the board's does not wait)."""
    total = writes[-1][1] if writes else 0.0
    held = [(f * total, f * total + d) for f, d in stalls]
    groups, group = [], []
    for write in writes:
        if group and (len(group) == chunk or write[1] - group[-1][1] > 0.005):
            groups.append(group)
            group = []
        group.append(write)
    reads = []
    groups.append(group)
    for group in groups:
        arrival = group[-1][1] + 0.001
        for start, end in held:
            if start <= arrival < end:
                arrival = end
        reads.append((b"".join(w[0] for w in group), arrival))
    return reads


def decode_run(sessions, stalls, chunk, boot_frames):
    decoder = Decoder(rate_hz=RATE)
    got = []
    arrival = 0.0
    for data, at in host_feed(wire_of(sessions, boot_frames), stalls, chunk):
        arrival = max(arrival, at)              # a monotonic clock
        got += decoder.feed(data, arrival)
    return got + decoder.flush(), decoder


def check_reconciles(sessions, got, decoder):
    stats = decoder.stats
    starts = [s.index for s in decoder.sessions]
    assert len(starts) == len(sessions), decoder.sessions
    assert stats.seq_restarts == len(sessions) - 1
    bounds = starts + [stats.frames]
    for i, s in enumerate(sessions):
        frames = bounds[i + 1] - bounds[i]
        lost = sum(g.length for g in decoder.gap_list if bounds[i] <= g.after_index + 1
                   < bounds[i + 1])
        assert frames + lost == s["n"], (i, frames, lost, s["n"])
        assert lost == len(s["drops"])
        kept = [(s["first"] + k) % SEQ_MODULUS for k in range(s["n"]) if k not in s["drops"]]
        assert [x.seq for x in got[bounds[i]:bounds[i + 1]]] == kept
    assert stats.duplicates == sum(len(s["dups"]) for s in sessions)
    assert stats.late == 0


def normalise(sessions):
    """A frame carries one fault: drops and dups on a swapped pair do not happen."""
    for s in sessions:
        s["dups"] -= s["drops"]
        s["swaps"] = {k for k in s["swaps"] if not {k, k + 1} & (s["drops"] | s["dups"])
                      and k + 1 not in s["swaps"] and k - 1 not in s["swaps"]}
    return sessions


@settings(max_examples=40, deadline=None)
@given(board_runs())
def test_a_board_with_boot_frames_is_counted_exactly_wherever_it_restarts(run):
    sessions, stalls, chunk = run
    sessions = normalise(sessions)
    got, decoder = decode_run(sessions, stalls, chunk, boot_frames=True)
    check_reconciles(sessions, got, decoder)
    assert decoder.stats.boot_frames == len(sessions)
    assert all(s.cause == "boot" for s in decoder.sessions)


def unambiguous_without_boot_frames(sessions, stalls=()) -> bool:
    """Whether the host can tell each restart of a board that sends no boot frame: not when the
    new count lands where the old one could have gone on in the time that passed (ahead of it
    by no more than that time allows), nor on the old count's last number without a silence
    the host saw, nor while the host was stalled (its clock saw neither)."""
    total = sum(s["silence_s"] + s["n"] / RATE for s in sessions)
    held = [(f * total - 0.01, f * total + d + 0.01) for f, d in stalls]
    elapsed = 0.0
    for before, s in zip(sessions, sessions[1:]):
        elapsed += before["n"] / RATE
        if any(start <= elapsed + s["silence_s"] and elapsed <= end for start, end in held):
            return False
        last = (before["first"] + before["n"] - 1) % SEQ_MODULUS
        ahead = (s["first"] - last - 1) % SEQ_MODULUS
        window_s = (s["silence_s"] + RESTART_SLACK_S + CLOCK_TOLERANCE * before["n"] / RATE
                    + 0.1)
        if ahead < HALF_MODULUS and ahead / RATE <= window_s:
            return False
        if s["first"] == last and s["silence_s"] < RESTART_SILENCE_S:
            return False
        elapsed += s["silence_s"]
    return True


@settings(max_examples=40, deadline=None)
@given(board_runs())
def test_a_board_without_boot_frames_is_counted_exactly_where_the_host_can_tell(run):
    sessions, stalls, chunk = run
    sessions = normalise(sessions)
    assume(unambiguous_without_boot_frames(sessions, stalls))
    got, decoder = decode_run(sessions, stalls, chunk, boot_frames=False)
    check_reconciles(sessions, got, decoder)
    assert decoder.stats.boot_frames == 0


@pytest.mark.parametrize("after", [1, 2, 500, 1023, 1024, 1025, 40_000, 65_535, 65_536, 70_000])
def test_a_restart_from_zero_at_any_point_is_a_restart(after):
    """The board resets after ``after`` frames and counts from 0 again (2,000 more frames),
    1.5 s later (an Arduino's bootloader): with and without a boot frame."""
    for boot in (True, False):
        sessions = [{"first": 0, "n": after, "silence_s": 0.0, "drops": set(), "dups": set(),
                     "swaps": set()},
                    {"first": 0, "n": 2000, "silence_s": 1.5, "drops": set(), "dups": set(),
                     "swaps": set()}]
        if not boot and not unambiguous_without_boot_frames(sessions):
            continue
        got, decoder = decode_run(sessions, [], 25, boot_frames=boot)
        stats = decoder.stats
        assert (stats.frames, stats.lost_samples, stats.duplicates) == (after + 2000, 0, 0), \
            (boot, stats)
        assert stats.seq_restarts == 1 and [s.index for s in decoder.sessions] == [0, after]


def test_the_host_rules_need_no_host_clock_for_a_count_that_goes_back():
    """Decoding a file (no arrival times): two frames continuing a count behind ours are a
    restart (RTP's probation), a lone repeated frame is a duplicate."""
    restarted = list(range(500)) + list(range(20))     # 0..19 were delivered: not "backward"
    data = b"".join(encode_binary(s, 1, 1) for s in restarted)
    got, decoder = decode_all(data)
    assert [s.seq for s in got] == restarted and decoder.stats.duplicates == 0
    assert [s.cause for s in decoder.sessions] == ["start", "sequence"]
    repeated = [500, 501, 502, 501, 503, 504]
    got, decoder = decode_all(b"".join(encode_binary(s, 1, 1) for s in repeated))
    assert [s.seq for s in got] == [500, 501, 502, 503, 504]
    assert (decoder.stats.duplicates, decoder.stats.seq_restarts) == (1, 0)


def test_a_lost_first_sample_after_a_boot_frame_is_a_gap_of_its_session():
    data = (b"".join(encode_binary(s, 1, 1) for s in range(100)) + encode_boot("binary", 0)
            + b"".join(encode_binary(s, 1, 1) for s in range(2, 50)))
    got, decoder = decode_all(data)
    assert decoder.stats.lost_samples == 2 and decoder.stats.seq_restarts == 1
    assert decoder.gap_list[-1].length == 2 and decoder.sessions[-1].first_seq == 0


def test_find_gaps_never_spans_a_session():
    from snn_antenna.bridge.wire.protocol import find_gaps

    seq = np.array(list(range(40_000)) + list(range(2000)))
    assert find_gaps(seq) != []                         # read alone, a gap of 25,536
    assert find_gaps(seq, [(0, None), (40_000, None)]) == []
    assert find_gaps(np.array([5, 6, 3, 4]), [(0, None), (2, 0)])[0].length == 3


@pytest.mark.slow
@settings(max_examples=300, deadline=None)
@given(board_runs(max_sessions=6, max_len=3000))
def test_many_more_boards_with_and_without_boot_frames(run):
    sessions, stalls, chunk = run
    sessions = normalise(sessions)
    got, decoder = decode_run(sessions, stalls, chunk, boot_frames=True)
    check_reconciles(sessions, got, decoder)
    if unambiguous_without_boot_frames(sessions, stalls):
        got, decoder = decode_run(sessions, stalls, chunk, boot_frames=False)
        check_reconciles(sessions, got, decoder)
