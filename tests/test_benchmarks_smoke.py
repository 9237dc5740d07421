"""The benchmarks run, and measure what they claim to: every frame in, every value out.

Nothing here looks at timings; they mean nothing at these sizes. What is
checked is structure: each benchmark ran the transactions it says it ran,
got every reply, and reports the rows, units and targets of the issue.
"""

from __future__ import annotations

import importlib
import os
import subprocess
import sys
from pathlib import Path
from types import ModuleType
from typing import TYPE_CHECKING

import pytest

from sj300_async import BusTiming, InverterStatus, MonitorData, TripHistory
from sj300_async.sj300 import AckReply, DataReply, NakReply, ReplyParser

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
    assert "| benchmark | ours | reference | unit | reference is |" in out
    assert out.count("| codec: ") == 3
    assert out.count("| pymodbus 3.") == 3


# -- the harness ---------------------------------------------------------------------


def _harness() -> ModuleType:
    return importlib.import_module("benchmarks._harness")


@pytest.fixture
def harness(monkeypatch: pytest.MonkeyPatch) -> ModuleType:
    monkeypatch.syspath_prepend(str(ROOT))
    return _harness()


def test_ratio_reads_as_times_better_whatever_the_unit(harness: ModuleType) -> None:
    result = harness.Result
    assert result("rate", 300.0, 100.0, "x/s", 3.0).ratio == 3.0
    assert result("rate", 300.0, 100.0, "x/s", 3.0).met is True
    cost = result("cpu", 60.0, 30.0, "µs", 1.0, higher_is_better=False)
    assert cost.ratio == 0.5
    assert cost.met is False
    assert result("latency", 40.0, None, "µs").ratio is None
    assert result("latency", 40.0, None, "µs", 1.0).met is None
    # No growth at all against a growth budget: infinitely better, and met.
    growth = result("rss", 0.0, 1.0, "MB", 1.0, higher_is_better=False)
    assert growth.ratio == float("inf")
    assert growth.met is True


def test_table_names_each_reference_and_shows_efficiencies_in_percent(
    harness: ModuleType,
) -> None:
    result = harness.Result
    table = harness.markdown_table(
        [
            result("codec", 2.0, 1.0, "frames/s", 3.0),
            result("wire", 100.0, 99.5, "ms", 0.99, False, against="wire limit", percent=True),
            result("latency", 40.0, None, "µs"),
        ],
        "pymodbus 3.x",
    )
    lines = table.splitlines()
    assert lines[0].split("|")[1:-1] == [
        " benchmark ",
        " ours ",
        " reference ",
        " unit ",
        " reference is ",
        " ours vs reference ",
        " target ",
        " met ",
    ]
    assert lines[2] == "| codec | 2 | 1 | frames/s | pymodbus 3.x | 2.00x | >= 3x | **no** |"
    assert lines[3] == "| wire | 100 | 99.5 | ms | wire limit | 99.5 % | >= 99 % | yes |"
    assert lines[4] == "| latency | 40 | — | µs | — | — | — | — |"


def test_best_time_runs_once_untimed_then_each_repeat(harness: ModuleType) -> None:
    calls: list[int] = []
    assert harness.best_time(lambda: calls.append(1), 3) >= 0
    assert len(calls) == 4
    with pytest.raises(ValueError, match="repeats"):
        harness.best_time(lambda: None, 0)


def test_every_registered_benchmark_has_the_module_contract(harness: ModuleType) -> None:
    benchmarks = importlib.import_module("benchmarks")
    assert list(benchmarks.BENCHMARKS) == [
        "codec",
        "tcp",
        "loopback",
        "latency",
        "wire",
        "scale",
        "gateway",
        "mqtt",
    ]
    for name in benchmarks.BENCHMARKS:
        module = benchmarks.load(name)
        assert name == module.TITLE
        assert module.USES_EVENT_LOOP is (name != "codec")
        assert callable(module.run)


# -- each benchmark, in its quick form -------------------------------------------------


def _quick(harness: ModuleType, loop: str = "asyncio") -> object:
    config: object = harness.Config(quick=True, repeats=1, loop=loop)
    return config


def test_tcp_times_both_stacks_on_their_own_servers(harness: ModuleType) -> None:
    bench_tcp = importlib.import_module("benchmarks.bench_tcp")
    section = bench_tcp.run(_quick(harness))  # raises unless every request was answered
    assert [(r.name, r.unit, r.target) for r in section.results] == [
        ("tcp: read_status vs 1 register", "requests/s", 2.5),
        ("tcp floor: bare asyncio round trip, read_status sizes", "requests/s", None),
        ("tcp: read_monitor vs 50 registers", "requests/s", 2.5),
        ("tcp floor: bare asyncio round trip, read_monitor sizes", "requests/s", None),
    ]
    assert all(r.ours > 0 and r.peer > 0 for r in section.results)
    assert any("processing_s=0" in note for note in section.notes)
    assert any("most any stack on the same loop" in note for note in section.notes)


def test_server_processes_end_with_their_context(harness: ModuleType) -> None:
    servers = importlib.import_module("benchmarks._servers")
    for kind in ("sj300", "pymodbus", "echo"):
        server = servers.ServerProcess(kind)
        with server:
            assert server.port > 0
            process = server._process
            assert process is not None
            assert process.poll() is None
        assert process.poll() is not None


def test_the_paced_pty_server_serves_its_drives(harness: ModuleType) -> None:
    servers = importlib.import_module("benchmarks._servers")
    with servers.ServerProcess("sj300-pty", baudrate=9600, drives=2) as server:
        assert server.path.startswith("/dev/")
        assert os.path.exists(server.path)
        process = server._process
        assert process is not None
        assert process.poll() is None
    assert process.poll() is not None


def test_loopback_counts_every_reply(harness: ModuleType) -> None:
    bench = importlib.import_module("benchmarks.bench_loopback")
    rates = bench.measure(_quick(harness))
    assert rates.transactions == 200
    # one task and eight tasks, each: one untimed run and one timed run
    assert rates.replies == 2 * 200 * 2
    assert 0 < rates.sim_s * rates.transactions < rates.one_task_s
    section = bench.run(_quick(harness))
    assert [(r.name, r.peer, r.against, r.target) for r in section.results] == [
        ("loopback: read_status, 1 task", 50_000, "target", 1.0),
        ("loopback: read_status, 8 tasks on 8 drives", 50_000, "target", 1.0),
        ("loopback: read_status, 1 task, simulator's share taken out", 50_000, "target", None),
    ]


def test_latency_times_every_transaction(harness: ModuleType) -> None:
    bench = importlib.import_module("benchmarks.bench_latency")
    lat = bench.measure(_quick(harness))
    assert len(lat.round_trips_s) == bench.QUICK_TRANSACTIONS
    assert list(lat.round_trips_s) == sorted(lat.round_trips_s)
    assert lat.percentile(0) == lat.round_trips_s[0]
    assert lat.percentile(100) == lat.round_trips_s[-1]
    assert lat.percentile(50) <= lat.percentile(99)
    assert lat.overhead(50) == lat.percentile(50) - lat.sim_s
    section = bench.run(_quick(harness))
    assert [(r.name, r.unit, r.peer) for r in section.results] == [
        ("latency: library overhead per transaction, p50", "µs", None),
        ("latency: library overhead per transaction, p99", "µs", None),
    ]


def test_wire_limit_is_computed_from_frames_bits_and_processing(harness: ModuleType) -> None:
    bench = importlib.import_module("benchmarks.bench_wire")
    cycles = bench.measure(_quick(harness))
    assert [c.line.baudrate for c in cycles] == [9600, 19200]
    for c in cycles:
        drives = bench.QUICK_DRIVES
        assert c.drives == drives
        assert c.transactions == 2 * drives
        # per drive: status (8 + 14 characters) and monitor (8 + 110), 10 bits each
        assert c.wire_s == pytest.approx(drives * 140 * 10 / c.line.baudrate)
        assert c.processing_s == pytest.approx(2 * drives * 0.001)
        # a guard after every reply but the cycle's last
        assert c.guard_s == pytest.approx(
            (2 * drives - 1) * BusTiming().guard_chars * 10 / c.line.baudrate
        )
        # no host can beat the wire: the paced line never delivers early
        assert c.cycle_s > c.wire_s
        assert c.traced_cycle_s > c.wire_s
    section = bench.run(_quick(harness))
    assert [(r.unit, r.against, r.target, r.percent) for r in section.results] == [
        ("ms", "wire limit", 0.99, True),
    ] * 2


def test_scale_polls_every_bus(harness: ModuleType) -> None:
    bench = importlib.import_module("benchmarks.bench_scale")
    scale = bench.measure(_quick(harness))  # raises if a bus was never polled
    assert scale.size == bench.QUICK
    assert scale.polls >= bench.QUICK.polls
    assert scale.errors == 0
    assert scale.cpu_s > 0
    assert scale.rss_before > 0
    assert scale.rss_after > 0
    assert len(scale.rss_trend) == 10
    section = bench.run(_quick(harness))
    assert [(r.unit, r.peer, r.target) for r in section.results] == [
        ("µs", 30.0, 1.0),
        ("µs", 30.0, None),
        ("MB", 1.0, 1.0),
    ]


def test_gateway_serves_every_read_from_its_cache(harness: ModuleType) -> None:
    bench = importlib.import_module("benchmarks.bench_gateway")
    config = _quick(harness)
    result = bench.measure(config)  # raises on a failed read or poll, or a read not served
    assert [(r.clients, r.gateway_rps > 0, r.peer_rps > 0) for r in result.rates] == [
        (1, True, True),
        (bench.CONCURRENT_CLIENTS, True, True),
    ]
    # both client set-ups: one untimed and one timed run each, all within the marks
    assert result.reads == 2 * 2 * bench.QUICK_READS
    polls = result.end.polls - result.start.polls
    assert polls >= bench.DRIVES  # at least one whole cycle between the marks
    assert result.line_requests == result.plan_requests == 2 * polls
    assert result.extra_per_1000_reads == 0
    section = bench.report(result, config)
    assert [(r.unit, r.target, r.against) for r in section.results] == [
        ("reads/s", bench.TARGET_RATIO, None),
        ("reads/s", None, None),
        ("requests", 1.0, "limit"),
    ]
    assert section.results[2].met is True
    assert any("+0 beyond the plan" in note for note in section.notes)


def test_mqtt_counts_every_state_and_times_every_change(harness: ModuleType) -> None:
    bench = importlib.import_module("benchmarks.bench_mqtt")
    config = _quick(harness)
    result = bench.measure(config)  # raises on a failed poll or a state that went missing
    cpu, latency = result.cpu, result.latency
    assert len(cpu.windows) == 1  # one timed window after the untimed one
    for window in cpu.windows:
        assert window.on_polls > 0
        assert window.off_polls > 0
        assert window.messages > 0
    # The fleet view got every state the gateway counted, and at most the batch in
    # flight when it stopped besides; every floor message.
    assert cpu.final.states <= cpu.received <= cpu.final.states + bench.MAX_IN_FLIGHT
    assert cpu.final.lost == 0
    assert len(cpu.floors) == 1
    assert cpu.floor_messages == bench.QUICK_FLOOR_MESSAGES
    sent = bench.FLOOR_WARM_UP + 2 * bench.QUICK_FLOOR_MESSAGES  # untimed, each way timed
    assert cpu.floor_received == cpu.floor_sent == sent
    assert len(latency.delays_s) == len(latency.after_poll_s) == bench.QUICK_CHANGES
    assert list(latency.delays_s) == sorted(latency.delays_s)
    assert latency.stats.cycles > 0
    assert latency.stats.failed == 0
    section = bench.report(result, config)
    assert [(r.unit, r.target, r.against, r.percent) for r in section.results] == [
        ("µs", bench.TARGET_CPU_RATIO, "aiomqtt loop", False),
        ("ms", None, None, False),
        ("ms", bench.TARGET_LATENCY_RATIO, "polling's floor", True),
    ]


# -- the command line ----------------------------------------------------------------


def _cli(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "benchmarks", "--quick", *args],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=120,
    )


def test_cli_quick_runs_every_benchmark_into_one_table() -> None:
    done = _cli()
    assert done.returncode == 0, done.stdout + done.stderr
    out = done.stdout
    for title in ("codec", "tcp", "loopback", "latency", "wire", "scale", "gateway", "mqtt"):
        assert f"\n## {title}\n" in out
    table = out.split("\n## results\n", 1)[1]
    rows = [line for line in table.splitlines() if line.startswith("| ") and "---" not in line]
    assert len(rows) == 1 + 3 + 4 + 3 + 2 + 2 + 3 + 3 + 3  # header + rows of each benchmark
    assert "**failed**" not in out


def test_cli_reports_a_failing_benchmark_and_goes_on(
    harness: ModuleType, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    benchmarks = importlib.import_module("benchmarks")
    cli = importlib.import_module("benchmarks.__main__")
    broken = ModuleType("benchmarks_broken_for_test")

    def run(config: object) -> object:
        raise RuntimeError("no replies")

    broken.TITLE = "broken"  # type: ignore[attr-defined]
    broken.USES_EVENT_LOOP = False  # type: ignore[attr-defined]
    broken.run = run  # type: ignore[attr-defined]
    monkeypatch.setitem(sys.modules, broken.__name__, broken)
    monkeypatch.setitem(benchmarks.BENCHMARKS, "broken", broken.__name__)
    status = cli.main(["--quick", "--only", "broken", "--only", "codec"])
    out = capsys.readouterr().out
    assert status == 1
    assert "**failed**: RuntimeError: no replies" in out
    assert out.count("| codec: ") == 3


def test_cli_uvloop_prints_a_table_of_its_own() -> None:
    import uvloop  # noqa: F401  (the dev extra installs it; a missing one must fail)

    done = _cli("--only", "codec", "--only", "loopback", "--uvloop")
    assert done.returncode == 0, done.stdout + done.stderr
    out = done.stdout
    assert "\n## loopback (uvloop)\n" in out
    assert "\n## codec (uvloop)\n" not in out  # no event loop: nothing to rerun
    uv_table = out.split("## results on uvloop", 1)[1]
    assert uv_table.count("| loopback: ") == 3


def test_tcp_runs_on_uvloop(harness: ModuleType) -> None:
    bench_tcp = importlib.import_module("benchmarks.bench_tcp")
    section = bench_tcp.run(_quick(harness, "uvloop"))
    assert len(section.results) == 4


def test_hotspots_profile_sees_the_library_per_transaction(harness: ModuleType) -> None:
    hotspots = importlib.import_module("benchmarks.hotspots")
    assert hotspots.layer("/x/sj300_async/bus/_arbiter.py") == "library"
    assert hotspots.layer("/x/sj300_async/simulator/sj300/_drive.py") == "simulator"
    assert hotspots.layer("/usr/lib/python3.11/asyncio/base_events.py") == "event loop"
    assert hotspots.layer("~") == "builtins"
    spots, done = hotspots.profile("loopback", 50)
    assert done == 50
    assert {"library", "simulator", "event loop"} <= {hotspots.layer(s.file) for s in spots}
    reads = [
        s for s in spots if s.where.startswith("sj300/_drive.py:") and s.function == "read_status"
    ]
    assert len(reads) == 1
    assert reads[0].calls >= 50  # a coroutine counts once more each time it resumes
