"""The whole gateway for a long time: do its memory and its descriptors stay flat? (issue 44)

``python -m benchmarks.bench_plant soak ...`` (:func:`main`) starts a
mosquitto of its own and one gateway child of bench_plant's ``all``
configuration (:func:`benchmarks.bench_plant._toml`): every northbound
(MQTT with discovery and Sparkplug on that broker, OPC UA, the workbench,
the Modbus listeners) with ``all``'s clients in a process of their own
(:mod:`benchmarks.plant_clients`: a JSON subscriber, a Sparkplug host, an OPC
UA subscription on every drive, event streams, a Modbus master per listener
reading the summary). The plant is ``--lines`` lines of ``--per-line``
simulated drives polled every ``--interval`` seconds (8 x 32 at 0.1 s by
default: issue 44's soak, a plant's hours compressed).

The workbench keeps a :data:`TREND_S` trend of each drive (``[http]
trend_s``; ``--trend-s``), not its default 15 minutes: the trend is a ring
of ``trend_s`` over the poll interval samples, compressed as it fills (issue
44), and at this plant's pace (about 0.15 s a poll: 8 lines of 32 drives do
not keep 0.1 s) 15 minutes of samples take 25 minutes to fill, growing some
40 KiB a drive all the while, 10 MiB for the plant: a soak judged from
minute 5 would count it. Two minutes' ring is full and wrapping by minute
4, so the soak exercises what a leak would hide in: a ring that drops its
oldest block as it seals a new one, over and over.

The drives never settle: each runs forward on a :data:`RAMP_S` ramp (both
ways), rises to :data:`HIGH_HZ`, then swings between :data:`LOW_HZ` and
:data:`HIGH_HZ` for ever, its setpoint (written through its line's bus, the
gateway's own arbiter) flipped to beyond the next turning point before it
gets there. So every poll changes every drive's output, and every
northbound reports by exception all the time, for the whole run.

The child prints ``ready`` once every drive's JSON state reached the broker,
every device is born on Sparkplug and the clients are subscribed; that is
the run's time 0. From then on it prints one line every ``--sample-every``
seconds (on a fixed schedule, not drifting) with its counters: samples
polled, JSON states confirmed by the broker, Sparkplug DDATA published, its
own CPU time. On each line this process (the parent) reads the child's
resident set (``VmRSS`` of ``/proc/PID/status``) and counts its open
descriptors (``/proc/PID/fd``): an observer outside the gateway, which
allocates nothing in it. For the last ``--check`` seconds the clients count
what they receive (their window, :mod:`benchmarks.plant_clients`); at
``--duration`` the child prints their figures and ends.

The verdict (:func:`verdict`): the RSS growth from the first sample at or
after ``--settle`` seconds (the rings fill before: the workbench records
300 s of each line's traffic) to the end, and the largest excursion above
it after, each as a percentage of that RSS; the open descriptors' minimum,
maximum and steady count after ``--settle`` (flat: never above the steady
count, :func:`fds_steady`); and whether the gateway still delivered:
samples, JSON states and Sparkplug DDATA in every interval, and every client
(MQTT, Sparkplug, OPC UA, the event streams, the Modbus masters) receiving
in the final window, none failed. A stalled gateway cannot pass: its memory
would be flat for the wrong reason.
"""

from __future__ import annotations

import argparse
import asyncio
import collections
import json
import os
import subprocess
import sys
import tempfile
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any, Final

__all__ = [
    "CHECK_S",
    "HIGH_HZ",
    "LOW_HZ",
    "RAMP_S",
    "TREND_S",
    "Sample",
    "Soak",
    "child_main",
    "main",
    "run_soak",
    "verdict",
]

#: Issue 44's soak: 8 lines of 32 drives at 0.1 s, 30 minutes, a sample a minute, the
#: verdict from the fifth minute.
LINES: Final = 8
DRIVES_PER_LINE: Final = 32
INTERVAL_S: Final = 0.1
DURATION_S: Final = 1800.0
SAMPLE_EVERY_S: Final = 60.0
SETTLE_S: Final = 300.0
#: The clients' final window, in which each must receive something.
CHECK_S: Final = 10.0
#: The workbench's trend window (module docstring): full, and wrapping, before SETTLE_S.
TREND_S: Final = 120.0
#: The drives' ramp: 0 Hz to the maximum frequency (A004) in this long, both ways.
RAMP_S: Final = 120.0
#: The output swings between these, once it has first risen to HIGH_HZ.
LOW_HZ: Final = 15.0
HIGH_HZ: Final = 35.0
#: How far past the next turning point a setpoint is written: the ramp never reaches it,
#: so the output keeps changing even if a flip comes late (by up to this over the rate).
MARGIN_HZ: Final = 5.0
#: From the child's start to ``ready`` at most: imports, the OPC UA address space, every
#: drive's first state on the broker and birth, the clients' subscriptions.
READY_TIMEOUT_S: Final = 180.0
#: What the child may take after its last sample: the clients' figures, the closes.
END_TIMEOUT_S: Final = 60.0
_ROOT: Final = Path(__file__).resolve().parent.parent


# -- the child: one gateway, its clients, its counters ---------------------------------------


@dataclass
class _Failed:
    """The swing's writes that failed: how many, and the first few messages (bounded: the
    soak's own bookkeeping must not grow in the process it measures)."""

    count: int = 0
    first: list[str] = field(default_factory=list)

    def add(self, message: str) -> None:
        self.count += 1
        if len(self.first) < 10:
            self.first.append(message)


async def _swing(gateway: Any, failed: _Failed) -> None:
    """Every drive forward, its output swinging for ever (module docstring); a write that
    fails is counted in *failed*, and the swing goes on."""
    from sj300_async import SJ300Error
    from sj300_async.sj300 import Drive

    drives: list[Drive] = []
    max_hz = 50.0
    for line in gateway.lines:
        simulator = line.bus.simulator
        for node in line.drives:
            simulated = simulator.drives[node]
            simulated.set_parameter("F002", round(RAMP_S * 100))  # acceleration time
            simulated.set_parameter("F003", round(RAMP_S * 100))  # deceleration time
            max_hz = simulated.parameters["A004"] / 10
            drive = line.bus.drive(node)
            assert isinstance(drive, Drive)
            drives.append(drive)
    rate = max_hz / RAMP_S  # Hz per second, both ways

    async def write(drive: Drive, hz: float, start: bool) -> None:
        try:
            await drive.set_frequency(hz)
            if start:
                await drive.run_forward()
        except SJ300Error as exc:
            failed.add(f"{drive.node}: {exc}")

    loop = asyncio.get_running_loop()
    began = loop.time()
    await asyncio.gather(*(write(d, HIGH_HZ + MARGIN_HZ, True) for d in drives))
    turn = began + HIGH_HZ / rate  # the first rise: 0 Hz to HIGH_HZ
    setpoint = LOW_HZ - MARGIN_HZ
    while True:
        await asyncio.sleep(max(0.0, turn - loop.time()))
        await asyncio.gather(*(write(d, setpoint, False) for d in drives))
        turn += (HIGH_HZ - LOW_HZ) / rate
        setpoint = HIGH_HZ + MARGIN_HZ if setpoint < LOW_HZ else LOW_HZ - MARGIN_HZ


def _emit(body: dict[str, Any]) -> None:
    print(json.dumps(body, allow_nan=False), flush=True)


async def _child(args: argparse.Namespace) -> None:
    from sj300_async.gateway import Gateway, parse_config

    from .bench_plant import SampleCount, _Clients, _delivery, _toml

    text = _toml(
        "all", args.lines, args.per_line, args.broker, Path(args.directory),
        interval_s=args.interval, trend_s=args.trend,
    )  # fmt: skip
    loop = asyncio.get_running_loop()
    began = loop.time()
    async with Gateway(parse_config(text, "soak.toml"), tune_collector=True) as gateway:
        started_s = loop.time() - began
        counted = SampleCount(gateway)
        drives = len(gateway.drives)
        bridge: Any = gateway.northbounds["mqtt"]
        edge: Any = gateway.northbounds["sparkplug"]
        failed = _Failed()
        swing = asyncio.create_task(_swing(gateway, failed), name="soak swing")
        clients = await _Clients.start(gateway, args.broker, summary=True)
        try:
            deadline = began + READY_TIMEOUT_S
            while not (
                len(bridge.stats.states) == drives and edge.stats.published["DBIRTH"] >= drives
            ):  # every drive's first state confirmed, every device born
                if swing.done():
                    raise RuntimeError("the drives' swing ended") from swing.exception()
                if loop.time() > deadline:
                    raise RuntimeError(f"not every drive visible within {READY_TIMEOUT_S:g} s")
                await asyncio.sleep(0.05)
            async with asyncio.timeout(max(1.0, deadline - loop.time())):
                await clients.ready(0.0)
            start = loop.time()
            _emit({"event": "ready", "drives": drives, "started_s": started_s,
                   "ready_s": start - began})  # fmt: skip

            def counters(at: float) -> dict[str, Any]:
                delivery = _delivery(bridge, edge)
                return {
                    "event": "sample",
                    "t_s": at - start,
                    "cpu_s": time.process_time(),
                    "samples": counted.samples,
                    "mqtt_states": delivery["mqtt_states"],
                    "mqtt_lost": delivery["mqtt_lost"],
                    "spb_ddata": edge.stats.published["DDATA"],
                    "swing_errors": failed.count,
                }

            _emit(counters(start))
            window = loop.call_at(start + max(0.0, args.duration - args.check),
                                  clients.command, "start")  # fmt: skip
            for tick in _ticks(args.duration, args.sample_every):
                await asyncio.sleep(max(0.0, start + tick - loop.time()))
                if swing.done():
                    break  # its failure is in the end's figures
                _emit(counters(loop.time()))
            window.cancel()
            figures = await clients.results()
        finally:
            await clients.close()
            swing.cancel()
            await asyncio.gather(swing, return_exceptions=True)
        failure = None
        if not swing.cancelled() and swing.exception() is not None:
            failure = repr(swing.exception())
        _emit({"event": "end", "clients": figures, "swing_failure": failure,
               "swing_error_messages": failed.first})  # fmt: skip


def _ticks(duration_s: float, every_s: float) -> list[float]:
    """The sample times after 0: every *every_s*, and *duration_s* (the last)."""
    every = [every_s * k for k in range(1, int(duration_s / every_s + 1e-9) + 1)]
    return [t for t in every if t < duration_s - 1e-6] + [duration_s]


def child_main(argv: Sequence[str] | None = None) -> None:
    """``python -m benchmarks._soak ...``: the gateway child (its lines on standard output)."""
    parser = argparse.ArgumentParser(prog="python -m benchmarks._soak")
    parser.add_argument("--lines", type=int, required=True)
    parser.add_argument("--per-line", type=int, required=True)
    parser.add_argument("--interval", type=float, required=True)
    parser.add_argument("--broker", type=int, required=True)
    parser.add_argument("--directory", required=True)
    parser.add_argument("--duration", type=float, required=True)
    parser.add_argument("--sample-every", type=float, required=True)
    parser.add_argument("--check", type=float, required=True)
    parser.add_argument("--trend", type=float, required=True)
    asyncio.run(_child(parser.parse_args(argv)))


# -- the parent: the broker, the child, the samples -------------------------------------------


@dataclass(frozen=True)
class Sample:
    """One sample of the child: its memory and descriptors, and its counters since the last."""

    #: Seconds since ``ready``.
    t_s: float
    rss_kib: int
    fds: int
    #: Per second over the interval before this sample (0 for the first).
    samples_per_s: float
    mqtt_states_per_s: float
    spb_ddata_per_s: float
    #: The child's CPU over the interval, as a share of one core.
    cpu_share: float


@dataclass(frozen=True)
class Soak:
    """A soak's series, the clients' final figures, and the :func:`verdict`."""

    lines: int
    per_line: int
    interval_s: float
    duration_s: float
    settle_s: float
    trend_s: float
    #: From the child's start: the gateway built, and every drive visible (``ready``).
    started_s: float
    ready_s: float
    series: tuple[Sample, ...]
    clients: dict[str, Any]
    swing_failure: str | None
    swing_errors: int
    mqtt_lost: int
    verdict: dict[str, Any] = field(default_factory=dict)

    def to_json(self) -> dict[str, Any]:
        return asdict(self)


def _rss_kib(pid: int) -> int:
    for line in Path(f"/proc/{pid}/status").read_text(encoding="ascii").splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1])
    raise RuntimeError(f"no VmRSS in /proc/{pid}/status")


def _fds(pid: int) -> int:
    return len(os.listdir(f"/proc/{pid}/fd"))


def _tail(path: Path) -> str:
    return path.read_text(encoding="utf-8", errors="replace")[-3000:]


async def _read(process: asyncio.subprocess.Process, timeout: float, log: Path) -> dict[str, Any]:
    assert process.stdout is not None
    async with asyncio.timeout(timeout):
        line = await process.stdout.readline()
    if not line:
        code = await process.wait()
        raise RuntimeError(f"the soak's gateway child exited ({code}): {_tail(log)}")
    body: dict[str, Any] = json.loads(line)
    return body


async def _soak(
    broker: int,
    directory: Path,
    *,
    lines: int,
    per_line: int,
    interval_s: float,
    duration_s: float,
    sample_every_s: float,
    settle_s: float,
    check_s: float,
    trend_s: float,
) -> Soak:
    command = [
        sys.executable, "-m", "benchmarks._soak",
        "--lines", str(lines), "--per-line", str(per_line), "--interval", str(interval_s),
        "--broker", str(broker), "--directory", str(directory),
        "--duration", str(duration_s), "--sample-every", str(sample_every_s),
        "--check", str(check_s), "--trend", str(trend_s),
    ]  # fmt: skip
    log = directory / "child.log"
    with log.open("wb") as stderr:  # a file, not a pipe: a chatty child never blocks on it
        process = await asyncio.create_subprocess_exec(
            *command, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=stderr, cwd=_ROOT
        )
    try:
        ready = await _read(process, READY_TIMEOUT_S, log)
        if ready["event"] != "ready":
            raise RuntimeError(f"the soak's child said {ready!r}, not ready")
        series: list[Sample] = []
        last: dict[str, Any] | None = None
        while True:
            body = await _read(process, sample_every_s + END_TIMEOUT_S, log)
            if body["event"] != "sample":
                break
            # Read as soon as the child says so: the child's state at that moment.
            rss, fds = _rss_kib(process.pid), _fds(process.pid)
            series.append(_sample(body, last, rss, fds))
            last = body
        if body["event"] != "end" or last is None:
            raise RuntimeError(f"the soak's child said {body!r}, not its end")
        async with asyncio.timeout(END_TIMEOUT_S):
            code = await process.wait()
        if code != 0:
            raise RuntimeError(f"the soak's gateway child failed ({code}): {_tail(log)}")
    finally:
        if process.returncode is None:
            process.kill()
            await process.wait()
    soak = Soak(
        lines=lines,
        per_line=per_line,
        interval_s=interval_s,
        duration_s=duration_s,
        settle_s=settle_s,
        trend_s=trend_s,
        started_s=ready["started_s"],
        ready_s=ready["ready_s"],
        series=tuple(series),
        clients=body["clients"],
        swing_failure=body["swing_failure"],
        swing_errors=last["swing_errors"],
        mqtt_lost=last["mqtt_lost"],
    )
    return replace(soak, verdict=verdict(soak))


def _sample(body: dict[str, Any], last: dict[str, Any] | None, rss: int, fds: int) -> Sample:
    if last is None:
        return Sample(body["t_s"], rss, fds, 0.0, 0.0, 0.0, 0.0)
    seconds = max(1e-9, body["t_s"] - last["t_s"])

    def rate(key: str) -> float:
        return float((body[key] - last[key]) / seconds)

    return Sample(
        body["t_s"], rss, fds, rate("samples"), rate("mqtt_states"), rate("spb_ddata"),
        rate("cpu_s"),
    )  # fmt: skip


def verdict(soak: Soak) -> dict[str, Any]:
    """What the soak shows (module docstring): memory and descriptors after ``settle_s``,
    and every problem with delivery (an empty list: none)."""
    series = soak.series
    after = [s for s in series if s.t_s >= soak.settle_s - 1e-6]
    problems = []
    for one in series[1:]:
        for key in ("samples_per_s", "mqtt_states_per_s", "spb_ddata_per_s"):
            if getattr(one, key) <= 0:
                problems.append(
                    f"no {key.removesuffix('_per_s')} in the interval to {one.t_s:.0f} s"
                )
    figures = soak.clients.get("clients", {})
    for name in ("mqtt", "sparkplug", "opcua", "http"):
        client = figures.get(name)
        if client is None or client["failure"] or not client["messages"]:
            problems.append(f"{name}'s client received nothing at the end: {client}")
    modbus = figures.get("modbus")
    if modbus is None or modbus["failure"] or not modbus["reads"] or modbus["errors"]:
        problems.append(f"the Modbus masters' reads at the end: {modbus}")
    if soak.swing_failure is not None:
        problems.append(f"the drives' swing failed: {soak.swing_failure}")
    out: dict[str, Any] = {"problems": problems, "samples_after_settle": len(after)}
    if len(after) >= 2:
        base = after[0].rss_kib
        out |= {
            "rss_at_settle_kib": base,
            "rss_end_kib": after[-1].rss_kib,
            "growth_pct": 100 * (after[-1].rss_kib - base) / base,
            "peak_growth_pct": 100 * (max(s.rss_kib for s in after) - base) / base,
            "growth_kib": after[-1].rss_kib - base,
            "peak_growth_kib": max(s.rss_kib for s in after) - base,
            "fds_min": min(s.fds for s in after),
            "fds_max": max(s.fds for s in after),
            "fds_steady": fds_steady(after),
        }
    else:
        problems.append(f"fewer than two samples after {soak.settle_s:g} s")
    return out


def fds_steady(after: Sequence[Sample]) -> int:
    """The descriptors the gateway holds steadily after settling: the count most samples
    saw (the earliest of equals).

    "Flat" is judged against it as a leak is: a sample above it is growth. One below is
    not: a client that reconnects (its stream cut for reading too slowly on a loaded
    machine, a master's time-out) closes its socket before it opens the next, and a
    clean clone's full suite once read 14 where every other sample read 17.
    """
    ((steady, _),) = collections.Counter(s.fds for s in after).most_common(1)
    return steady


def fds_flat(held: dict[str, Any]) -> bool:
    """No sample after settling held more descriptors than the steady count."""
    return bool(held["fds_max"] <= held["fds_steady"])


def run_soak(
    *,
    lines: int = LINES,
    per_line: int = DRIVES_PER_LINE,
    interval_s: float = INTERVAL_S,
    duration_s: float = DURATION_S,
    sample_every_s: float = SAMPLE_EVERY_S,
    settle_s: float = SETTLE_S,
    check_s: float = CHECK_S,
    trend_s: float = TREND_S,
) -> Soak:
    """One soak on a mosquitto of its own (module docstring); raises if the child fails."""
    from .bench_mqtt import _mosquitto

    if not 0 < check_s < duration_s:
        raise ValueError(f"the final window must lie within the run: 0 < {check_s} < {duration_s}")
    with _mosquitto() as broker, tempfile.TemporaryDirectory(prefix="bench_soak_") as directory:
        return asyncio.run(
            _soak(
                broker, Path(directory), lines=lines, per_line=per_line, interval_s=interval_s,
                duration_s=duration_s, sample_every_s=sample_every_s, settle_s=settle_s,
                check_s=check_s, trend_s=trend_s,
            )
        )  # fmt: skip


def summary(soak: Soak) -> str:
    """The series as a table, and the verdict: for a reader (the JSON has everything)."""
    out = [
        f"soak: {soak.lines} x {soak.per_line} drives at {soak.interval_s:g} s, "
        f"{soak.duration_s:g} s, trends of {soak.trend_s:g} s; gateway built in "
        f"{soak.started_s:.1f} s, every drive visible and the clients subscribed after "
        f"{soak.ready_s:.1f} s",
        "| t (s) | RSS (MiB) | fds | samples/s | JSON states/s | DDATA/s | CPU |",
        "|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for s in soak.series:
        out.append(
            f"| {s.t_s:.0f} | {s.rss_kib / 1024:.1f} | {s.fds} | {s.samples_per_s:.0f} | "
            f"{s.mqtt_states_per_s:.0f} | {s.spb_ddata_per_s:.0f} | {s.cpu_share:.0%} |"
        )
    out.append("verdict: " + json.dumps(soak.verdict))
    return "\n".join(out)


def main(argv: Sequence[str] | None = None) -> None:
    """``python -m benchmarks.bench_plant soak ...``: one soak, its table and verdict printed
    (and its JSON written with ``--json``); exit 1 when it does not hold."""
    parser = argparse.ArgumentParser(prog="python -m benchmarks.bench_plant soak")
    parser.add_argument("--lines", type=int, default=LINES)
    parser.add_argument("--per-line", type=int, default=DRIVES_PER_LINE)
    parser.add_argument("--interval", type=float, default=INTERVAL_S, help="poll interval (s)")
    parser.add_argument("--duration", type=float, default=DURATION_S, help="seconds from ready")
    parser.add_argument("--sample-every", type=float, default=SAMPLE_EVERY_S)
    parser.add_argument("--settle", type=float, default=SETTLE_S, help="growth counted from here")
    parser.add_argument("--check", type=float, default=CHECK_S, help="the clients' final window")
    parser.add_argument("--trend-s", type=float, default=TREND_S, help="the workbench's trend")
    parser.add_argument("--max-growth-pct", type=float, default=1.0)
    parser.add_argument("--json", metavar="PATH", help="also write the soak as JSON")
    args = parser.parse_args(argv)
    soak = run_soak(
        lines=args.lines, per_line=args.per_line, interval_s=args.interval,
        duration_s=args.duration, sample_every_s=args.sample_every, settle_s=args.settle,
        check_s=args.check, trend_s=args.trend_s,
    )  # fmt: skip
    print(summary(soak), flush=True)
    if args.json:
        Path(args.json).write_text(json.dumps(soak.to_json(), indent=2) + "\n", encoding="utf-8")
    held = soak.verdict
    ok = not held["problems"] and held["peak_growth_pct"] < args.max_growth_pct and fds_flat(held)
    sys.exit(0 if ok else 1)


if __name__ == "__main__":
    child_main()
