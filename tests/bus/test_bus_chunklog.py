"""A bus recorder's compact log of a line's chunks (bus/_chunklog.py).

A model check: whatever is appended, ``since(t)`` gives exactly the chunks
a plain list would (times to the microsecond), for every ``t`` inside what the log promises to keep
(the last ``keep_s`` seconds, the newest ``max_chunks``), and what it holds
beyond that is bounded: segments are judged when a new one starts.
"""

from __future__ import annotations

from typing import Literal

from hypothesis import given
from hypothesis import strategies as st

from sj300_async.bus import ChunkLog, Kept

_CHUNKS = st.lists(
    st.tuples(
        st.floats(min_value=0.0, max_value=2.0),
        st.sampled_from(["tx", "rx"]),
        st.binary(max_size=12),
        st.booleans(),
    ),
    max_size=200,
)


def _fill(log: ChunkLog, chunks: list[tuple[float, str, bytes, bool]]) -> list[Kept]:
    """Append *chunks* (each with its gap from the one before); the plain list of them."""
    at, kept = 100.0, []
    for gap, direction, data, early in chunks:
        at += gap
        side: Literal["tx", "rx"] = "rx" if direction == "rx" else "tx"
        log.append(at, side, data, early)
        kept.append((round(at * 1e6) / 1e6, side, data, early))  # kept to the microsecond
    return kept


@given(_CHUNKS, st.floats(min_value=0.0, max_value=1.0))
def test_what_is_kept_reads_back_exactly(
    chunks: list[tuple[float, str, bytes, bool]], share: float
) -> None:
    log = ChunkLog(keep_s=1e9, max_chunks=10_000, segment=7)
    kept = _fill(log, chunks)
    assert len(log) == len(kept)
    assert list(log.since(-1.0)) == kept
    if kept:  # from any time inside it: what a list filtered from there gives
        start = kept[0][0] + share * (kept[-1][0] - kept[0][0])
        assert list(log.since(start)) == [c for c in kept if c[0] >= start]


@given(_CHUNKS)
def test_old_chunks_expire_by_whole_segments(chunks: list[tuple[float, str, bytes, bool]]) -> None:
    log = ChunkLog(keep_s=5.0, max_chunks=10_000, segment=7)
    kept = _fill(log, chunks)
    if not kept:
        return
    horizon = kept[-1][0] - 5.0
    recent = [c for c in kept if c[0] >= horizon]
    assert list(log.since(horizon)) == recent
    # Judged when the last segment started: everything since that moment's horizon,
    # and at most the rest of the oldest segment before it.
    judged = kept[(len(kept) - 1) // 7 * 7][0] - 5.0
    since_judged = [c for c in kept if c[0] >= judged]
    assert len(since_judged) <= len(log) < len(since_judged) + 7


@given(st.integers(min_value=0, max_value=120))
def test_at_most_about_max_chunks_are_kept(count: int) -> None:
    log = ChunkLog(keep_s=1e9, max_chunks=30, segment=8)
    kept = _fill(log, [(0.01, "tx", bytes([i % 256]), False) for i in range(count)])
    newest = kept[-30:]
    assert list(log.since(-1.0))[-len(newest) :] == newest
    assert min(count, 30) <= len(log) < 30 + 2 * 8


def test_an_empty_log_gives_nothing() -> None:
    log = ChunkLog(keep_s=300.0, max_chunks=100)
    assert len(log) == 0
    assert list(log.since(0.0)) == []


def test_a_polled_line_is_kept_in_a_few_bytes_a_chunk() -> None:
    """The plant's traffic (a request and a reply per read, the replies' values moving,
    each chunk a few hundred microseconds late or early): sealed segments hold it in 2.5
    bytes a chunk (3.0 with the steps and marks not shuffled), against 25 in plain arrays
    and their 12 of times and marks."""
    log = ChunkLog(keep_s=300.0, max_chunks=50_000)
    at, kept = 1000.0, []
    for cycle in range(400):
        for node in range(1, 33):
            request = b"\x02%02d01\r" % node
            reply = b"\x02%02d%08d%08d\x06\r" % (node, 5000 + cycle % 7, 120 + node)
            for direction, data in (("tx", request), ("rx", reply)):
                at += 0.0037 + (cycle * 64 + node * 2 + (direction == "rx")) * 7919 % 401 / 1e6
                side: Literal["tx", "rx"] = "rx" if direction == "rx" else "tx"
                log.append(at, side, data, False)
                kept.append((round(at * 1e6) / 1e6, side, data, False))
    assert list(log.since(-1.0)) == kept
    plain = sum(len(c[2]) + 12 for c in kept)
    assert log.nbytes < 2.75 * len(kept) < plain / 8
