"""The benchmarks run, and measure what they claim to: every frame in, every value out.

Nothing here looks at timings; they mean nothing at these sizes.
"""

from __future__ import annotations

import importlib
import subprocess
import sys
from pathlib import Path
from types import ModuleType
from typing import TYPE_CHECKING

import pytest

from sj300_async import (
    AckReply,
    DataReply,
    InverterStatus,
    MonitorData,
    NakReply,
    ReplyParser,
    TripHistory,
)

if TYPE_CHECKING:
    from benchmarks.bench_codec import Workload

ROOT = Path(__file__).resolve().parent.parent
FRAMES = 300
SEED = 300


@pytest.fixture
def bench_codec(monkeypatch: pytest.MonkeyPatch) -> ModuleType:
    # The benchmarks are a top-level folder, not part of the installed package.
    monkeypatch.syspath_prepend(str(ROOT))
    return importlib.import_module("benchmarks.bench_codec")


@pytest.fixture
def workload(bench_codec: ModuleType) -> Workload:
    built: Workload = bench_codec.build_workload(FRAMES, SEED)
    return built


def test_stream_composition_matches_the_mix(bench_codec: ModuleType, workload: Workload) -> None:
    from benchmarks._streams import KINDS

    streams = workload.streams
    assert len(streams.ours) == len(streams.peer) == FRAMES
    counts = [streams.count(i) for i in range(len(KINDS))]
    assert sum(counts) == FRAMES
    # 35 / 30 / 20 / 12 / 2 / 1 percent of 300
    assert counts == [105, 90, 60, 36, 6, 3]
    sizes: dict[str, set[int]] = {kind.label: set() for kind in KINDS}
    for index, frame in zip(streams.kinds, streams.ours, strict=True):
        sizes[KINDS[index].label].add(len(frame))
    assert sizes == {
        "03 monitor": {110},
        "04 status": {14},
        "06 parameter (ACK + 8)": {15},
        "ACK (00/01/02/07 writes)": {7},
        "05 trip history": {446},
        "NAK": {9},
    }


def test_peer_frames_are_size_matched(workload: Workload) -> None:
    streams = workload.streams
    pairs = {(len(o), len(p)) for o, p in zip(streams.ours, streams.peer, strict=True)}
    # Nearest Modbus ASCII length (11 + 4N for N registers); 11 is Modbus's shortest.
    assert pairs == {(110, 111), (14, 15), (15, 15), (7, 11), (446, 447), (9, 11)}
    assert all(p.startswith(b":") and p.endswith(b"\r\n") for p in streams.peer)


def test_chunks_are_uart_sized_and_cover_both_streams(workload: Workload) -> None:
    w = workload
    assert b"".join(w.ours_chunks) == b"".join(w.streams.ours)
    assert b"".join(w.peer_chunks) == b"".join(w.streams.peer)
    for chunks in (w.ours_chunks, w.peer_chunks):
        assert all(1 <= len(c) <= 64 for c in chunks)
    # Same chunk-size sequence on both sides, up to where the shorter stream ends.
    ours_sizes = [len(c) for c in w.ours_chunks[:-1]]
    peer_sizes = [len(c) for c in w.peer_chunks[: len(ours_sizes)]]
    assert ours_sizes == peer_sizes


def test_our_side_decodes_every_frame_to_its_type(
    bench_codec: ModuleType, workload: Workload
) -> None:
    values = bench_codec.decode_ours(workload.ours_chunks)
    assert len(values) == FRAMES
    by_type: dict[type, int] = {}
    for value in values:
        by_type[type(value)] = by_type.get(type(value), 0) + 1
    assert by_type == {
        MonitorData: 105,
        InverterStatus: 90,
        int: 60,
        AckReply: 36,
        TripHistory: 6,
        NakReply: 3,
    }
    parser = ReplyParser()
    for chunk in workload.ours_chunks:
        parser.feed(chunk)
    assert parser.stats.frames == FRAMES
    assert parser.stats.bad_frames == parser.stats.discarded_bytes == 0


def test_peer_side_decodes_every_frame(bench_codec: ModuleType, workload: Workload) -> None:
    pdus = bench_codec.decode_peer(workload.peer_chunks)
    names = [type(p).__name__ for p in pdus]
    assert len(pdus) == FRAMES
    assert names.count("ReadHoldingRegistersResponse") == 105 + 90 + 60 + 6
    assert names.count("ReadExceptionStatusResponse") == 36
    assert names.count("ExceptionResponse") == 3
    register_counts = sorted({len(p.registers) for p in pdus if p.function_code == 3})
    assert register_counts == [1, 25, 109]


def test_framing_only_sees_every_frame(bench_codec: ModuleType, workload: Workload) -> None:
    events = bench_codec.frame_ours(workload.ours_chunks)
    assert len(events) == FRAMES
    assert sum(isinstance(e, DataReply) for e in events) == 105 + 90 + 6
    assert len(bench_codec.frame_peer(workload.peer_chunks)) == FRAMES


def test_run_quick_reports_the_three_rows(bench_codec: ModuleType) -> None:
    from benchmarks._harness import Config

    section = bench_codec.run(Config(quick=True, repeats=1))
    assert [(r.name, r.unit) for r in section.results] == [
        ("codec: parse + typed decode", "frames/s"),
        ("codec: parse + typed decode", "MB/s"),
        ("codec: framing only (no payload decode)", "frames/s"),
    ]
    assert all(r.ours > 0 and r.peer > 0 for r in section.results)
    assert section.results[0].target == 3.0
    assert any("| 05 trip history | 2% | 6 | 446 |" in line for line in section.notes)


def test_cli_prints_environment_and_table() -> None:
    done = subprocess.run(
        [sys.executable, "-m", "benchmarks", "--quick", "--only", "codec"],
        cwd=ROOT,
        capture_output=True,
        text=True,
        check=True,
        timeout=60,
    )
    out = done.stdout
    assert f"Python {sys.version.split()[0]}" in out
    assert "pymodbus 3." in out
    assert "Stream: 300 replies" in out
    assert "| benchmark | ours | pymodbus" in out
    assert out.count("| codec: ") == 3
