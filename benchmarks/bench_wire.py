"""Wire efficiency: how close a polling cycle comes to what the line itself allows.

32 simulated drives behind a baud-paced line: a simulator process serves
them on a pseudo-terminal (``python -m benchmarks._servers sj300-pty``),
holding every character for its wire time in both directions on one
half-duplex line, each drive waiting its processing time (the simulator's
default 1 ms, a real drive's order of magnitude) after a request before it
answers; C078 is 0. The host opens the pty as a serial port
(``serial:///dev/pts/N``, pyserial) on the benchmark's event loop, as it
would a USB adapter. A :class:`~sj300_async.Poller` with ``interval_s=0``
reads status (04) and monitor (03) of every drive; one cycle is 64
transactions.

The limit of a cycle is what no host can beat::

    wire limit = sum over transactions of (request + reply characters)
                 x bits per character / baud  +  the drives' processing time

Why a process and a pty rather than the in-memory paced line: the paced
line's timers are the wire, and on the host's loop they would fire late by
epoll's millisecond rounding, charging the emulation's error to the host.
The simulator process runs them on a select()-based loop with microsecond
time-outs, and the host wakes when bytes arrive, as it does on a real UART.

The library rests ``BusTiming.guard_chars`` character times after each
reply before it writes again; the default is 0 (see ``_timing.py``), and
the notes' guard column shows what a configured guard would add. The notes
break the rest down,
from the trace of every frame: the host's turnaround from a reply to the
next request beyond the guard (the library's work and the loop's wake-up)
and how late the simulated line delivered each reply's last character past
its ideal time (the simulator process's timers and the pty's hand-over,
not the library: a real UART hands bytes over as they arrive).
"""

from __future__ import annotations

import asyncio
from dataclasses import dataclass

from sj300_async import BusTiming, LineSettings, Poller, open_bus
from sj300_async.bus import TraceRecord
from sj300_async.simulator.sj300 import DEFAULT_PROCESSING_S

from ._harness import Config, Result, Section, new_runner
from ._servers import ServerProcess

_GUARD_CHARS = BusTiming().guard_chars

__all__ = [
    "LINES",
    "TITLE",
    "USES_EVENT_LOOP",
    "Cycle",
    "efficiency",
    "measure",
    "measure_runs",
    "run",
]

TITLE = "wire"
USES_EVENT_LOOP = True
#: The line settings measured: (baud rate, bytesize, parity, stop bits).
LINES: tuple[LineSettings, ...] = (LineSettings(9600), LineSettings(19200))
#: Drives on the line, full and ``--quick``.
DRIVES = 32
QUICK_DRIVES = 2
#: Untraced cycles measured per line (the best counts), full runs.
CYCLES = 3
#: The project's aim: cycle time within 1 % of the wire limit.
TARGET_EFFICIENCY = 0.99


@dataclass(frozen=True, slots=True)
class Cycle:
    """One measured polling cycle and its limits, in seconds."""

    line: LineSettings
    drives: int
    transactions: int
    #: The cycle as the poller measured it (``BusPollStats.last_cycle_s``), untraced.
    cycle_s: float
    #: A second cycle, with every frame traced for the breakdown below.
    traced_cycle_s: float
    #: Wire time of every request and reply character.
    wire_s: float
    #: The drives' processing time (and C078 wait, here 0), summed.
    processing_s: float
    #: The guard intervals the timing policy requires within the cycle.
    guard_s: float
    #: Summed time from each reply's arrival to the next request, beyond the guard.
    turnaround_s: float
    #: Summed lateness of each reply's arrival past its ideal wire time.
    line_late_s: float

    @property
    def limit_s(self) -> float:
        """Wire time plus processing: no host can poll faster."""
        return self.wire_s + self.processing_s

    @property
    def guarded_limit_s(self) -> float:
        """The limit plus the guard intervals the library's policy adds."""
        return self.limit_s + self.guard_s


def _line_label(line: LineSettings) -> str:
    return f"{line.baudrate} {line.bytesize}{line.parity}{line.stopbits}"


async def _measure_line(line: LineSettings, drives: int, path: str, repeats: int) -> Cycle:
    """The best of *repeats* cycles as a user's poll runs them, then one traced for the breakdown.

    Best of several, as every other benchmark here: a cycle is one sample of
    a noisy machine, and the best one is the closest to what the code costs.
    """
    timing = BusTiming()
    cycle_s = min([await _poll_one_cycle(line, drives, path, timing, None) for _ in range(repeats)])
    trace: list[TraceRecord] = []
    traced_s = await _poll_one_cycle(line, drives, path, timing, trace)
    return _analyse(trace, line, drives, cycle_s, traced_s, timing.guard(line))


async def _poll_one_cycle(
    line: LineSettings,
    drives: int,
    path: str,
    timing: BusTiming,
    trace: list[TraceRecord] | None,
) -> float:
    nodes = range(1, drives + 1)
    url = (
        f"serial://{path}?baudrate={line.baudrate}&bytesize={line.bytesize}"
        f"&parity={line.parity}&stopbits={line.stopbits}"
    )
    hook = None if trace is None else trace.append
    async with open_bus(url, timing=timing, trace=hook) as bus:
        poller = Poller(interval_s=0, reads=("status", "monitor"))
        poller.add(bus, nodes)
        done: asyncio.Future[None] = asyncio.get_running_loop().create_future()
        polled = 0

        def count(_sample: object) -> None:
            nonlocal polled
            polled += 1
            if polled == drives and not done.done():
                done.set_result(None)

        poller.on_sample(count)
        async with poller:
            await done
            # The poller updated its statistics right after publishing the last
            # sample, before this task could resume; the next cycle has just begun.
            stats = poller.bus_stats(bus)
            if stats.cycles != 1 or stats.errors:
                raise RuntimeError(f"expected one clean polling cycle: {stats}")
            return stats.last_cycle_s


@dataclass(frozen=True, slots=True)
class _Reply:
    """A reply as the trace saw it: its bytes, and when its last chunk arrived."""

    length: int
    timestamp: float


def _transactions(trace: list[TraceRecord]) -> list[tuple[TraceRecord, _Reply]]:
    """Pair each request with the chunks that came back before the next one."""
    pairs: list[tuple[TraceRecord, _Reply]] = []
    request: TraceRecord | None = None
    length, done = 0, None
    for record in [*trace, None]:
        if record is not None and record.direction == "rx":
            length += len(record.data)
            if record.events:
                done = record.timestamp
            continue
        if request is not None:
            if done is None:
                break  # unanswered: the cycle is over
            pairs.append((request, _Reply(length, done)))
        request, length, done = record, 0, None
    return pairs


def _analyse(
    trace: list[TraceRecord],
    line: LineSettings,
    drives: int,
    cycle_s: float,
    traced_s: float,
    guard_s: float,
) -> Cycle:
    # Trace of one cycle: a request (tx), then its reply in one or more chunks
    # (rx). The poller may have written the first request of the next cycle
    # before it was stopped: complete transactions only.
    pairs = _transactions(trace)[: 2 * drives]
    if len(pairs) != 2 * drives:
        raise RuntimeError(f"expected {2 * drives} clean transactions, traced {len(pairs)}")
    char_s = line.char_time_s
    processing = DEFAULT_PROCESSING_S
    wire = sum((len(t.data) + r.length) * char_s for t, r in pairs)
    late = sum(
        (r.timestamp - t.timestamp) - (len(t.data) + r.length) * char_s - processing
        for t, r in pairs
    )
    gaps = [pairs[i + 1][0].timestamp - pairs[i][1].timestamp for i in range(len(pairs) - 1)]
    return Cycle(
        line=line,
        drives=drives,
        transactions=len(pairs),
        cycle_s=cycle_s,
        traced_cycle_s=traced_s,
        wire_s=wire,
        processing_s=processing * len(pairs),
        guard_s=guard_s * len(gaps),
        turnaround_s=sum(gaps) - guard_s * len(gaps),
        line_late_s=late,
    )


def measure(config: Config) -> list[Cycle]:
    """Poll one cycle on each line of :data:`LINES`; return the cycles."""
    drives = QUICK_DRIVES if config.quick else DRIVES
    repeats = 1 if config.quick else CYCLES
    cycles: list[Cycle] = []
    with new_runner(config.loop) as runner:
        for line in LINES:
            if (line.bytesize, line.parity, line.stopbits) != (8, "N", 1):
                raise ValueError(f"the pty simulator paces 8N1 only, not {line}")
            with ServerProcess("sj300-pty", baudrate=line.baudrate, drives=drives) as server:
                measured = _measure_line(line, drives, server.path, repeats)
                cycles.append(runner.run(measured))
    return cycles


def measure_runs(config: Config) -> list[list[Cycle]]:
    """:func:`measure` ``config.wire_runs`` times, each with fresh simulator processes."""
    return [measure(config) for _ in range(config.wire_runs)]


def efficiency(cycle: Cycle) -> float:
    """The wire limit as a share of the measured cycle (the row's ratio; target 0.99)."""
    return cycle.limit_s / cycle.cycle_s


def _notes(runs: list[list[Cycle]], config: Config) -> tuple[str, ...]:
    first = runs[0][0]
    ms = 1e3
    lines = [
        f"{first.drives} drives at nodes 1..{first.drives} served on a pty paced at the baud "
        "rate by a simulator process (`python -m benchmarks._servers sj300-pty`), opened as "
        f"`serial:///dev/pts/N`; C078 = 0, processing {DEFAULT_PROCESSING_S * ms:g} ms per "
        "request (the simulator's default); a `Poller(interval_s=0, reads=('status', "
        "'monitor'))`, one cycle of "
        f"{first.transactions} transactions (8-byte requests, 14- and 110-byte replies). "
        f"The cycle is the best of {CYCLES} of the poller's own `BusPollStats.last_cycle_s`, "
        "each on a fresh bus without a trace, as a user polls; the breakdown comes from one "
        "more cycle on a bus that traces every frame (building a record per chunk costs time "
        "of its own: the traced cycle can be longer).",
        "",
        "| line | cycle ms | traced cycle ms | wire ms | processing ms "
        f"| guard ms ({_GUARD_CHARS:g} chars) | host turnaround beyond guard ms "
        "| simulated line late ms | unaccounted ms |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for index, cycles in enumerate(runs):
        for c in cycles:
            lines.append(_breakdown(c, index + 1 if len(runs) > 1 else None))
    lines += _EXPLANATION
    if len(runs) > 1:
        lines += ["", f"{len(runs)} runs, each with fresh simulator processes:"]
        for index, line in enumerate(LINES):
            shares = [efficiency(cycles[index]) for cycles in runs]
            met = sum(share >= TARGET_EFFICIENCY for share in shares)
            lines.append(
                f"- {_line_label(line)}: {met} of {len(runs)} runs >= "
                f"{TARGET_EFFICIENCY * 100:g} % ("
                + ", ".join(f"{share * 100:.1f} %" for share in shares)
                + ")"
            )
    if config.loop == "uvloop":
        lines.append(
            "On uvloop, `loop.time()` (which stamps the host's trace) has a resolution of "
            "1 ms: the breakdown is rough and a column may go negative."
        )
    return tuple(lines)


def _breakdown(c: Cycle, run: int | None) -> str:
    ms = 1e3
    rest = c.traced_cycle_s - c.guarded_limit_s - c.turnaround_s - c.line_late_s
    label = _line_label(c.line) + ("" if run is None else f" (run {run})")
    return (
        f"| {label} | {c.cycle_s * ms:.1f} | {c.traced_cycle_s * ms:.1f} "
        f"| {c.wire_s * ms:.1f} | {c.processing_s * ms:.1f} | {c.guard_s * ms:.1f} "
        f"| {c.turnaround_s * ms:.1f} | {c.line_late_s * ms:.1f} | {rest * ms:.1f} |"
    )


_EXPLANATION = [
    "",
    "Breakdown of the traced cycle. Host turnaround: from the reply's arrival to the next "
    "request's write, beyond the guard (the library's own work, the trace's, and the "
    "event loop's wake-up). Simulated line late: "
    "the reply's last character reached the host after its ideal time (the simulator "
    "process's wake-ups, its timers' slack, and the pty's hand-over in both directions; "
    "a real UART has no such delay). Unaccounted: the poller's work between cycles and "
    "before the first request.",
]


def run(config: Config) -> Section:
    """Measure polling cycles against the wire limit at each line setting.

    With ``config.wire_runs`` > 1, each line's row is the median run (the lower of
    the two middle ones for an even count), and one more row per line counts the
    runs that met the target.
    """
    runs = measure_runs(config)
    results: list[Result] = []
    for index, line in enumerate(LINES):
        cycles = sorted((cycles[index] for cycles in runs), key=efficiency)
        c = cycles[(len(cycles) - 1) // 2]
        label = _line_label(line)
        results.append(
            Result(
                f"wire {label}: {c.drives} drives, status + monitor cycle vs wire limit",
                c.cycle_s * 1e3,
                c.limit_s * 1e3,
                "ms",
                TARGET_EFFICIENCY,
                higher_is_better=False,
                against="wire limit",
                percent=True,
            )
        )
        if len(runs) > 1:
            met = sum(efficiency(cycle) >= TARGET_EFFICIENCY for cycle in cycles)
            results.append(
                Result(
                    f"wire {label}: runs at >= {TARGET_EFFICIENCY * 100:g} % of the wire limit",
                    met,
                    len(runs),
                    "runs",
                    1.0,
                    against="runs made",
                    percent=True,
                )
            )
    return Section(TITLE, _notes(runs, config), tuple(results))
