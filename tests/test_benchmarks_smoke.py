"""The benchmarks run, and measure what they claim to: every frame in, every value out.

Nothing here looks at timings; they mean nothing at these sizes. What is
checked is structure: each benchmark ran the transactions it says it ran,
got every reply, and reports the rows, units and targets of the issue.
"""

from __future__ import annotations

import asyncio
import importlib
import os
import platform
import subprocess
import sys
from pathlib import Path
from types import ModuleType
from typing import TYPE_CHECKING

import pytest

from sj300_async import BusTiming, InverterStatus, MonitorData, TripHistory
from sj300_async.sj300 import AckReply, DataReply, NakReply, ReplyParser, decode_status

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
    assert section.results[0].target == 3.5
    assert any("| 05 trip history | 2% | 6 | 446 |" in line for line in section.notes)
    # the spread of the same-run ratio, pair by pair (one pair in a quick run)
    assert any(
        "per interleaved pair of runs" in line and "of 1 pairs >= 3.5x" in line
        for line in section.notes
    )


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


def test_cost_rows_can_read_as_a_multiple_of_their_reference(harness: ModuleType) -> None:
    result = harness.Result
    # ours <= 0.7x the reference: the ratio kept as "times better" (1 / 0.7), shown as ours / ref
    cpu = result("cpu", 23.0, 33.0, "µs", 1 / 0.7, False, against="pymodbus", as_multiple=True)
    assert cpu.met is True
    table = harness.markdown_table([cpu], "pymodbus")
    assert table.splitlines()[2] == "| cpu | 23 | 33 | µs | pymodbus | 0.70x | <= 0.7x | yes |"
    worse = result("scale", 31.0, 5.0, "µs", 1 / 6, False, as_multiple=True)
    assert worse.met is False
    assert "| 6.20x | <= 6x | **no** |" in harness.markdown_table([worse], "x")


def test_interleave_rotates_the_order_and_times_cpu(harness: ModuleType) -> None:
    order: list[str] = []
    timings = harness.interleave(
        [lambda: order.append("a"), lambda: order.append("b"), lambda: order.append("c")], 3
    )
    # one untimed run each, then each repeat starts one side further on
    assert order == ["a", "b", "c", "a", "b", "c", "b", "c", "a", "c", "a", "b"]
    assert [len(t.wall_s) for t in timings] == [3, 3, 3]
    assert all(len(t.cpu_s) == 3 and t.best_cpu_s >= 0 for t in timings)
    assert timings[0].best_wall_s == min(timings[0].wall_s)
    with pytest.raises(ValueError, match="repeats"):
        harness.interleave([lambda: None], 0)


def test_best_time_runs_once_untimed_then_each_repeat(harness: ModuleType) -> None:
    calls: list[int] = []
    assert harness.best_time(lambda: calls.append(1), 3) >= 0
    assert len(calls) == 4
    with pytest.raises(ValueError, match="repeats"):
        harness.best_time(lambda: None, 0)


#: Every benchmark, in the order they run and print.
ALL_BENCHMARKS = ("codec", "tcp", "loopback", "latency", "wire", "scale", "gateway", "mqtt",
                  "workbench", "opcua", "plant", "attack")  # fmt: skip


def test_every_registered_benchmark_has_the_module_contract(harness: ModuleType) -> None:
    benchmarks = importlib.import_module("benchmarks")
    assert tuple(benchmarks.BENCHMARKS) == ALL_BENCHMARKS
    for name in benchmarks.BENCHMARKS:
        module = benchmarks.load(name)
        assert name == module.TITLE
        assert module.USES_EVENT_LOOP is (name != "codec")
        assert callable(module.run)


# -- each benchmark, in its quick form -------------------------------------------------


def _quick(harness: ModuleType, loop: str = "asyncio") -> object:
    config: object = harness.Config(quick=True, repeats=1, loop=loop)
    return config


TCP_ROWS = [
    ("tcp: read_status vs bare asyncio floor, same minimal responder", "requests/s", 0.9),
    (
        "tcp: client CPU per round trip, read_status vs read_holding_registers(count=4), "
        "minimal responders",
        "µs",
        pytest.approx(1 / 0.7),
    ),
    ("tcp: read_status vs read_holding_registers(count=4), minimal responders", "requests/s", None),
    ("tcp: read_status vs bare asyncio floor on the same (buffered) read path", "requests/s", None),
    ("tcp floor: bare asyncio round trip vs pymodbus, minimal responders", "requests/s", None),
    (
        "tcp floor: client CPU per bare asyncio round trip vs pymodbus, minimal responders",
        "µs",
        None,
    ),
    # the second table: each stack on its own server
    ("tcp: read_status vs 1 register", "requests/s", None),
    ("tcp floor: bare asyncio round trip, read_status sizes", "requests/s", None),
    ("tcp: read_monitor vs 50 registers", "requests/s", None),
    ("tcp floor: bare asyncio round trip, read_monitor sizes", "requests/s", None),
]


def test_tcp_times_both_stacks_on_their_own_servers(harness: ModuleType) -> None:
    bench_tcp = importlib.import_module("benchmarks.bench_tcp")
    section = bench_tcp.run(_quick(harness))  # raises unless every request was answered
    assert [(r.name, r.unit, r.target) for r in section.results] == TCP_ROWS
    assert all(r.ours > 0 and r.peer > 0 for r in section.results)
    assert any("processing_s=0" in note for note in section.notes)
    assert any("most any stack on the same loop" in note for note in section.notes)
    assert any(note.startswith("Targets, this run: ours / floor = ") for note in section.notes)
    # the headline's table: floor, ours, pymodbus, each against its minimal responder,
    # and the floor again on the buffered read path
    assert sum(note.startswith("| ") and "minimal`" in note for note in section.notes) == 2
    assert sum(note.startswith("| ") and "| `echo` |" in note for note in section.notes) == 2
    assert any(note.startswith("Against the same read path (no target)") for note in section.notes)


def test_tcp_minimal_responders_answer_every_request(harness: ModuleType) -> None:
    bench_tcp = importlib.import_module("benchmarks.bench_tcp")
    config = _quick(harness)
    m = bench_tcp.measure_minimal(config)  # raises unless our bus counted every reply
    for side in (m.floor, m.ours, m.pymodbus, m.floor_buffered):
        assert side.requests == bench_tcp.QUICK_REQUESTS
        assert len(side.timing.wall_s) == len(side.timing.cpu_s) == 1
        assert side.rps > 0
        assert side.cpu_s > 0
        assert side.server_cpu_s > 0
    assert m.ours_vs_floor == m.ours.rps / m.floor.rps
    assert m.cpu_vs_pymodbus == m.ours.cpu_s / m.pymodbus.cpu_s
    assert m.ours_vs_buffered_floor == m.ours.rps / m.floor_buffered.rps


def test_minimal_responders_give_valid_replies(harness: ModuleType) -> None:
    servers = importlib.import_module("benchmarks._servers")
    events = list(ReplyParser().feed(servers.SJ300_STATUS_REPLY))
    assert len(servers.SJ300_STATUS_REPLY) == 14
    assert len(events) == 1
    assert isinstance(events[0], DataReply)
    assert events[0].node == 1
    assert isinstance(decode_status(events[0].data), InverterStatus)
    # Modbus TCP: transaction id (2) + protocol 0, length 11, device 1, function 3, 8 bytes
    assert len(servers.MODBUS_REPLY) + 2 == 17
    assert servers.MODBUS_REPLY[:7] == bytes((0, 0, 0, 11, 1, 3, 8))


def test_server_processes_end_with_their_context(harness: ModuleType) -> None:
    servers = importlib.import_module("benchmarks._servers")
    for kind in ("sj300", "pymodbus", "echo", "sj300-minimal", "modbus-minimal"):
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
    assert rates.floor_s > 0
    section = bench.run(_quick(harness))
    assert [(r.name, r.peer, r.against, r.target) for r in section.results][:3] == [
        ("loopback: read_status, 1 task", 50_000, "target", 1.0),
        ("loopback: read_status, 8 tasks on 8 drives", 50_000, "target", 1.0),
        ("loopback: read_status, 1 task, simulator's share taken out", 50_000, "target", None),
    ]
    # the same run's in-memory asyncio floor, as a reference
    floor = section.results[3]
    assert (floor.name, floor.against, floor.target) == (
        "loopback: read_status, 1 task vs in-memory asyncio floor, same run",
        "in-memory floor",
        None,
    )
    assert floor.ours == section.results[0].ours
    assert floor.peer > 0


def test_latency_times_every_transaction(harness: ModuleType) -> None:
    bench = importlib.import_module("benchmarks.bench_latency")
    lat = bench.measure(_quick(harness))
    assert len(lat.round_trips_s) == bench.QUICK_TRANSACTIONS
    assert list(lat.round_trips_s) == sorted(lat.round_trips_s)
    assert lat.percentile(0) == lat.round_trips_s[0]
    assert lat.percentile(100) == lat.round_trips_s[-1]
    assert lat.percentile(50) <= lat.percentile(99)
    assert lat.overhead(50) == lat.percentile(50) - lat.sim_s
    assert len(lat.floor_s) == bench.QUICK_TRANSACTIONS
    assert 0 < lat.floor(50) <= lat.floor(99)
    section = bench.run(_quick(harness))
    assert [(r.name, r.unit, r.peer is None) for r in section.results] == [
        ("latency: library overhead per transaction, p50", "µs", True),
        ("latency: library overhead per transaction, p99", "µs", True),
        (
            "latency: library overhead per transaction, p50 vs in-memory asyncio floor, same run",
            "µs",
            False,
        ),
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


def test_wire_runs_n_times_and_counts_the_runs_that_met_the_target(
    harness: ModuleType,
) -> None:
    bench = importlib.import_module("benchmarks.bench_wire")
    config = harness.Config(quick=True, repeats=1, wire_runs=2)
    section = bench.run(config)
    rows = section.results
    assert [(r.unit, r.against, r.target) for r in rows] == [
        ("ms", "wire limit", 0.99),
        ("runs", "runs made", 1.0),
    ] * 2
    for headline, count in (rows[0:2], rows[2:4]):
        assert count.peer == 2
        assert count.ours in (0, 1, 2)
        assert count.met is (count.ours == 2)
        # the headline is the lower of the two runs (the median of an even count)
        assert headline.met is (count.ours == 2)
    assert any(" runs >= 99 % (" in note for note in section.notes)
    assert sum("(run 2)" in note for note in section.notes) == 2


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
    assert len(scale.cpu_windows_s) == 10
    assert scale.best_library_cpu_per_poll_s == min(scale.cpu_windows_s) - scale.sim_s
    ref = scale.reference
    assert ref is not None
    assert ref.tcp_floor_s > 0
    assert ref.memory_floor_s > 0
    assert ref.runs == 2  # one before the polls, one after
    section = bench.run(_quick(harness))
    assert [(r.unit, r.against, r.target) for r in section.results] == [
        ("µs", "in-memory floor", pytest.approx(1 / bench.TARGET_VS_MEMORY_FLOOR)),
        ("µs", "tcp floor", None),
        ("µs", "old target", None),
        ("µs", "old target", None),
        ("MB", "target", 1.0),
    ]
    assert section.results[0].as_multiple


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
    # The fleet view got every state the gateway counted, and besides at most those of
    # the batch its stop cancelled in flight, which it counts lost (some may reach the
    # broker); nothing else is lost. Every floor message.
    assert cpu.final.lost <= bench.MAX_IN_FLIGHT
    assert cpu.final.states <= cpu.received <= cpu.final.states + cpu.final.lost
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


def test_workbench_streams_every_sample_and_times_the_overview(harness: ModuleType) -> None:
    bench = importlib.import_module("benchmarks.bench_workbench")
    config = _quick(harness)
    # Raises on a failed poll, a stream that missed a sample, or a page that never
    # showed every drive.
    result = bench.measure(config)
    cpu, browser, memory = result.cpu, result.browser, result.memory
    assert len(cpu.windows) == 1  # one timed window after the untimed one
    for window in cpu.windows:
        assert window.streams_samples > 0
        assert window.quiet_samples > 0
        assert window.events > 0
    # Every sample published in the timed window reached each stream once (checked by
    # measure), and the clients kept up: nothing replaced while they read.
    assert cpu.checked_samples > 0
    assert sum(w.replaced for w in cpu.windows) == 0
    assert cpu.metrics_replaced == cpu.final.replaced
    assert 0 < cpu.metrics_sent <= cpu.final.sent
    assert cpu.final.streams == bench.STREAMS
    assert cpu.final.failed == 0
    # The browser: one timed load of each page, the overview's phases in order.
    assert len(browser.overview) == len(browser.json) == bench.QUICK_LOADS
    for load in browser.overview:
        assert load.first_event_ms is not None
        assert 0 < load.html_ms <= load.ready_ms
        assert load.html_ms <= load.first_event_ms <= load.shown_ms  # rows come from events
    assert all(load.first_event_ms is None for load in browser.json)
    assert browser.delays_s
    assert list(browser.delays_s) == sorted(browser.delays_s)
    assert len(browser.arrival_s) <= len(browser.delays_s)
    assert browser.errors == ()
    # The trends: the default window at the default interval, measured at least as large
    # as its arrays' samples.
    assert memory.drives == bench.QUICK_MEMORY_DRIVES
    assert memory.capacity == 1980
    assert memory.payload == 1980 * 16
    assert 0 < memory.nbytes < memory.payload / 2  # sealed: a ramp packs
    assert memory.per_drive >= memory.nbytes
    section = bench.report(result, config)
    assert [(r.unit, r.target, r.against, r.as_multiple) for r in section.results] == [
        ("µs", bench.TARGET_CPU_RATIO, "no stream", True),
        ("ms", bench.TARGET_FIRST_PAINT_RATIO, "JSON page", True),
        ("ms", None, "poll interval", True),
        ("ms", bench.TARGET_UPDATE_RATIO, "poll interval", True),
        ("bytes", bench.TARGET_MEMORY_RATIO, "payload", True),
    ]


def test_opcua_matches_every_notification_and_times_the_start_up(harness: ModuleType) -> None:
    bench = importlib.import_module("benchmarks.bench_opcua")
    config = _quick(harness)
    # Raises on a child that did not start, a monitored item refused, a first value that
    # never came, or a window whose notifications matched no published sample.
    result = bench.measure(config)
    cpu, big = result.cpu, result.big
    assert len(cpu.windows) == 1  # one timed window after the untimed one
    for window in cpu.windows:
        assert window.bare_polls > 0
        assert window.mqtt_polls > 0
        assert window.opcua_polls > 0
        assert window.states > 0  # MQTT states acknowledged by the broker
        assert window.pushed > 0  # the running drives' values changed at every poll
        assert window.notifications > 0
    assert cpu.drives == big.drives == bench.QUICK_DRIVES
    assert cpu.items > big.small_items
    # One start-up round (no untimed one in --quick), the gateway's own and asyncua's parts.
    assert len(big.startups) == bench.QUICK_STARTUP_REPEATS
    for startup in big.startups:
        assert 0 < startup.gateway_s < startup.with_opcua_s
        assert 0 < startup.init_s < startup.startup_s <= startup.with_opcua_s
        assert 0 < startup.commit_s < startup.startup_s
        assert startup.init_alone_s > 0
        assert startup.nodes > big.big_items
    # One frequency item per drive; then every variable of the namespace.
    assert big.small_items == bench.QUICK_DRIVES
    assert big.big_items > big.big_data_items > 0
    assert big.subscriptions == 1
    for delays in (big.alone, big.with_all):
        assert 0 < delays.matched <= delays.published
        assert len(delays.delays_s) == delays.matched
        assert list(delays.delays_s) == sorted(delays.delays_s)
        assert delays.delays_s[0] > 0  # the sample came before its notification
    section = bench.report(result, config)
    assert [(r.unit, r.target, r.against, r.as_multiple) for r in section.results] == [
        ("ms", None, "poll interval", True),
        ("ms", None, "poll interval", True),
        ("µs", bench.TARGET_CPU_RATIO, "MQTT bridge", True),
        ("µs", None, "bare poll", True),
        ("µs", None, "bare poll", True),
        ("ms", None, "gateway start", True),
        ("ms", None, "OPC UA start-up", True),
        ("µs", None, f"{bench.QUICK_DRIVES} items", True),
        ("ms", None, f"{bench.QUICK_DRIVES} items", True),
    ]


def test_plant_runs_its_gateways_and_counts_every_sample(harness: ModuleType) -> None:
    bench = importlib.import_module("benchmarks.bench_plant")
    # Raises on a child that failed (its stderr's tail in the message).
    children = bench.measure(_quick(harness))
    assert set(children) == {"bare", "all"}
    for child in children.values():
        assert child.drives == bench.QUICK_LINES * bench.QUICK_DRIVES_PER_LINE
        assert all(rate > 0 for rate in child.samples_per_s)
        assert child.rss_bytes > 0
    whole = children["all"].delivery
    assert whole["mqtt_samples"] > 0
    assert whole["spb_samples"] > 0
    assert set(children["all"].visible_s) == {"mqtt", "sparkplug"}  # every drive, both ways
    assert children["all"].opcua_startup_s > 0
    assert children["bare"].visible_s == {}
    # all's clients, a process of their own, heard every drive through every northbound
    assert children["bare"].clients is None
    clients = children["all"].clients["clients"]
    drives = bench.QUICK_LINES * bench.QUICK_DRIVES_PER_LINE
    for name in ("mqtt", "sparkplug", "opcua", "http"):
        figures = clients[name]
        assert figures["failure"] is None, name
        assert figures["drives"] == drives, name
        assert figures["messages"] > 0, name  # in the window: a delay each
        assert 0 < figures["p99_ms"] < 1000 * bench.INTERVAL_S, name
    modbus = clients["modbus"]
    assert modbus["failure"] is None
    assert modbus["summary"] is True  # the masters read the summary (unit 255)
    assert modbus["reads"] > 0
    assert modbus["errors"] == {}
    # two gateways of one line each on one broker: the fleet view and the host see all
    two = bench.measure_two_gateways(_quick(harness))
    assert two.fleet_drives == two.born == two.drives == drives
    assert two.fleet_s is not None
    assert two.born_s is not None
    assert [child.drives for child in two.children] == [drives // 2, drives // 2]
    # the heap children (tracemalloc), at their quick size: bare and one northbound
    memory = importlib.import_module("benchmarks._memory")
    heap = bench.measure_heap(_quick(harness))
    assert set(heap) == set(memory.QUICK_HEAP_CONFIGURATIONS)
    for which, traced in heap.items():
        assert traced.drives == memory.QUICK_HEAP_LINES * memory.QUICK_HEAP_DRIVES_PER_LINE
        assert traced.traced_bytes > 0
        assert "sj300_async/simulator/sj300/" in traced.by_package, which  # the bench's drives
    assert "sj300_async/gateway/mqtt/" in heap["mqtt"].by_package
    assert "sj300_async/gateway/mqtt/" not in heap["bare"].by_package
    section = bench.report(children, two)
    assert [(r.unit, r.target, r.against) for r in section.results] == [
        ("µs", bench.TARGET_ALL, "bare poll"),
        ("share", 1.0, "every sample"),
        ("share", 1.0, "every sample"),
        ("KiB", None, "bare poll"),
        *[("ms", 1.0, "poll interval")] * 4,
        *[("drives", 1.0, "every drive")] * 2,
    ]
    # the memory table: a row per child (RSS), the heap children's after (their packages)
    notes = bench.report(children, two, heap).notes
    rows = [note.split(" | ")[0] for note in notes if note.startswith("| ")][1:]  # no header
    assert rows == ["| bare", "| all", "| mqtt"]
    assert "`sj300_async/gateway/mqtt/` +" in next(n for n in notes if n.startswith("| mqtt"))


def test_plant_memory_is_per_drive_against_the_bare_poll_by_package() -> None:
    bench = importlib.import_module("benchmarks.bench_plant")
    memory = importlib.import_module("benchmarks._memory")
    kib = 1024 * 8  # a KiB per drive, of 8 drives

    def child(which: str, rss_kib: int) -> object:
        return bench.Child(which, 8, (1e-4,), (8.0,), rss_kib * kib, 0.1, None, {}, {})

    def heap(which: str, **by_package: int) -> object:
        return memory.Heap(which, 8, {k: v * kib for k, v in by_package.items()}, 0, 0.1, 1.0)

    children = {"bare": child("bare", 40), "all": child("all", 400)}
    traced = {
        "bare": heap("bare", sim=15, asyncio=5),
        "all": heap("all", sim=15, asyncio=7, asyncua=300, http=20),
    }
    rows = memory.memory_rows(children, traced)
    assert [(r.name, r.ours, r.peer) for r in rows] == [
        ("plant: RSS per drive, every northbound on", 400, 40),
        ("plant: traced heap per drive, every northbound on (8 drives)", 342, 20),
    ]
    table = [n for n in memory.memory_notes(children, traced) if n.startswith("| ")]
    assert table[1] == "| bare | 40 |  | 20.0 |  | `sim` 15.0, `asyncio` 5.0 |"
    assert table[2] == (  # the largest deltas first; none for a package both hold alike (sim)
        "| all | 400 | +360 | 342.0 | +322.0 | `asyncua` +300.0, `http` +20.0, `asyncio` +2.0 |"
    )
    assert memory.package_of(memory.__file__) == "benchmarks/"
    assert memory.package_of(asyncio.__file__) == "stdlib:asyncio"


# -- the command line ----------------------------------------------------------------


def _cli(*args: str, env: dict[str, str] | None = None) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "benchmarks", "--quick", *args],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
    )


def test_cli_quick_joins_the_benchmarks_it_runs_into_one_table() -> None:
    # Three, not all twelve (78 s of a suite's worker): the others each have a smoke test
    # of their own above; the attack's is this one. One without the event loop (codec),
    # one on it (loopback), and the attack's plant.
    titles = ("codec", "loopback", "attack")
    done = _cli(*(arg for title in titles for arg in ("--only", title)))
    assert done.returncode == 0, done.stdout + done.stderr
    out = done.stdout
    for title in titles:
        assert f"\n## {title}\n" in out
    # The run re-executed itself with glibc's malloc thresholds pinned (benchmarks._allocator).
    if sys.platform == "linux" and platform.libc_ver()[0] == "glibc":
        assert "- allocator: glibc malloc thresholds pinned" in out
    table = out.split("\n## results\n", 1)[1]
    rows = [line for line in table.splitlines() if line.startswith("| ") and "---" not in line]
    # header + rows: codec's 3, loopback's 4, attack's 3 (idle, attacked, the ratio)
    assert len(rows) == 1 + 3 + 4 + 3
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
    assert uv_table.count("| loopback: ") == 4


def test_tcp_runs_on_uvloop(harness: ModuleType) -> None:
    bench_tcp = importlib.import_module("benchmarks.bench_tcp")
    section = bench_tcp.run(_quick(harness, "uvloop"))
    assert len(section.results) == len(TCP_ROWS)


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


# -- the profile of a TCP round trip -------------------------------------------------

_ANNOTATE = """\
--------------------------------------------------------------------------------
Ir
--------------------------------------------------------------------------------
1,000,000 (100.0%)  PROGRAM TOTALS

--------------------------------------------------------------------------------
Ir                  file:function
--------------------------------------------------------------------------------
400,000 (40.00%)  Python/ceval.c:_PyEval_EvalFrameDefault [/lib/libpython3.11.so]
100,000 (10.00%)  Python/ceval.c:_PyEval_EvalFrameDefault'2 [/lib/libpython3.11.so]
 50,000 ( 5.00%)  build/Python-3.11.7/./Include/object.h:builtin_sum
 20,000 ( 2.00%)  ???:send [/usr/lib/x86_64-linux-gnu/libc.so.6]
"""


def test_profile_tcp_reads_callgrind_annotate(harness: ModuleType) -> None:
    profile_tcp = importlib.import_module("benchmarks.profile_tcp")
    total, counts = profile_tcp.parse_annotate(_ANNOTATE)
    assert total == 1_000_000
    assert counts == {
        ("ceval.c", "_PyEval_EvalFrameDefault"): 500_000,  # recursion levels added up
        ("object.h", "builtin_sum"): 50_000,
        ("libc.so.6", "send"): 20_000,  # no debug information: the object names it
    }


def test_profile_tcp_prints_where_the_time_goes(
    harness: ModuleType, capsys: pytest.CaptureFixture[str]
) -> None:
    profile_tcp = importlib.import_module("benchmarks.profile_tcp")
    assert profile_tcp.main(["-n", "50", "--top", "8", "--no-callgrind"]) == 0
    out = capsys.readouterr().out
    assert "| ours |" in out
    assert "| bare asyncio floor |" in out
    assert "50 round trips under cProfile" in out
    assert "_arbiter.py" in out  # the library's own functions are listed
    assert "Bytecodes per round trip: ours " in out
    assert "(skipped: --no-callgrind)" in out


# -- bench-compare ---------------------------------------------------------------------


def test_compare_flags_a_row_by_its_same_run_ratio(harness: ModuleType) -> None:
    compare = importlib.import_module("benchmarks.compare")
    row = compare.Row
    # The machine was 20 % slower in the second run: ours and its reference fell alike.
    old = [row("tcp", 10_000.0, "requests/s", peer=8_000.0), row("lat", 10.0, "µs")]
    new = [row("tcp", 8_000.0, "requests/s", peer=6_400.0), row("lat", 12.0, "µs")]
    assert compare.same_run_ratio(old[0]) == 1.25
    assert compare.same_run_ratio(row("cpu", 20.0, "µs", peer=30.0)) == 1.5
    assert compare.same_run_ratio(old[1]) is None
    table, worse = compare.render(old, new, "REF")
    lines = table.splitlines()
    assert lines[2].endswith("| -20.0 % | 1.25x | 1.25x | +0.0 % |  |")  # not flagged
    assert "**worse by more than 5 %**" in lines[3]  # no reference: the value decides
    assert worse == 1
    # the printed table of an older commit gives the reference too
    parsed = compare.parse_table(
        "## results\n\n| benchmark | ours | reference | unit |\n|---|---:|---:|---|\n"
        "| tcp | 10,000 | 8,000 | requests/s | pymodbus | 1.25x | — | — |\n"
    )
    assert parsed == [row("tcp", 10_000.0, "requests/s", "asyncio", None, 8_000.0)]


def test_the_allocator_pin_adds_to_the_tunables_once_and_can_be_turned_off(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.syspath_prepend(str(ROOT))
    allocator = importlib.import_module("benchmarks._allocator")
    if not (sys.platform == "linux" and platform.libc_ver()[0] == "glibc"):
        assert allocator.pinned_environment({"A": "1"}) == {"A": "1"}  # nothing to pin
        return
    pinned = allocator.pinned_environment({"A": "1"})
    assert pinned == {"A": "1", "GLIBC_TUNABLES": allocator.TUNABLES}
    assert allocator.pinned_environment(pinned) == pinned  # once
    other = allocator.pinned_environment({"GLIBC_TUNABLES": "glibc.malloc.tcache_count=0"})
    assert other["GLIBC_TUNABLES"] == f"glibc.malloc.tcache_count=0:{allocator.TUNABLES}"
    dynamic = {"SJ300_BENCH_DYNAMIC_MALLOC": "1"}
    assert allocator.pinned_environment(dynamic) == dynamic


def test_a_run_told_to_keep_dynamic_thresholds_says_so() -> None:
    env = {k: v for k, v in os.environ.items() if k != "GLIBC_TUNABLES"}
    env["SJ300_BENCH_DYNAMIC_MALLOC"] = "1"
    done = _cli("--only", "codec", env=env)
    assert done.returncode == 0, done.stdout + done.stderr
    assert "- allocator: glibc's dynamic malloc thresholds (not pinned)" in done.stdout


def test_plant_a_repeated_configuration_counts_the_best_window_of_both_children() -> None:
    bench = importlib.import_module("benchmarks.bench_plant")
    assert set(bench.REPEATED) == {"bare", "all"}  # the goal's two, run twice
    first = bench.Child("bare", 8, (2e-4, 1.5e-4), (8.0, 8.0), 100, 0.1, None, {}, {})
    again = bench.Child("bare", 8, (1.2e-4, 3e-4), (7.0, 8.0), 200, 0.2, None, {}, {})
    merged = first.merged(again)
    assert merged.best_cpu_s == 1.2e-4
    assert merged.cpu_per_sample_s == (2e-4, 1.5e-4, 1.2e-4, 3e-4)
    assert merged.samples_per_s == (8.0, 8.0, 7.0, 8.0)
    assert (merged.rss_bytes, merged.started_s) == (100, 0.1)  # the first child's
