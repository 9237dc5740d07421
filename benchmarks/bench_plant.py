"""The whole gateway at plant scale: 64 lines of 32 drives at 1 Hz, each northbound's cost.

Issue 30's measurement, first part: what each northbound adds to the
gateway's CPU per drive sample, against the bare poll's own CPU per sample
in the same run, whether every drive state reaches the broker (none
replaced unsent), the memory per drive, and the time from start to every
drive visible on MQTT (each drive's first state; every Sparkplug birth).

Each configuration runs in a process of its own (``python -m
benchmarks.bench_plant gateway --with ...``), one after the other, so that
each has the machine's two cores to itself and its RSS is its own:

- ``bare``: the lines alone, no northbound;
- ``mqtt``: ``[mqtt]`` with the JSON topics and Home Assistant discovery
  (QoS 1, the default), on a mosquitto of its own on loopback;
- ``sparkplug``: ``[mqtt] sparkplug = true``, ``state_topics = false``;
- ``mqtt+sparkplug``: both, each sample's state message built once for both;
- ``opcua``: ``[opcua]`` without security, no client;
- ``http``: ``[http]`` (the workbench, /metrics), no client;
- ``modbus``: nine ``[[modbus.listeners]]`` of seven lines each, no client;
- ``all``: every one of them at once.

Every line is ``sim://?nodes=1-32`` (the same URL: 64 simulators of their
own), polled every second (status and monitor), no trip-history or
set-frequency reads beside the poll, so a sample is a poll. Every drive
runs forward on a long ramp, so its output changes at every poll: the
worst case for publishing by exception. A child lets the gateway run
:data:`WARM_UP_S` seconds (the births, the discovery configs, OPC UA's
start-up), then measures :data:`WINDOWS` windows of :data:`WINDOW_S`
seconds: its CPU (``time.process_time()``, the simulators' included, alike
on every side) per sample polled; the best window counts.

Rows: ``all`` against ``bare`` (the issue's goal: at most twice), each
northbound alone against ``bare`` (information), the JSON topics' and
Sparkplug's share of samples neither replaced unsent nor lost (goal:
every one; the states confirmed in a window are shown too, but up to a
chunk of 256 is in flight at each of its edges), RSS per drive, and the
time to every drive visible.

Not yet measured (issue 30 goes on): clients on the servers (Modbus
masters reading, an OPC UA subscription, event streams on the
workbench), the delay from a sample to each northbound's client, and two
gateways feeding one broker.

``--quick`` measures nothing: two lines of four drives, one short window,
and only ``bare`` and ``all``.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import math
import os
import subprocess
import sys
import tempfile
import textwrap
import time
from collections.abc import Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Final

from ._harness import Config, Result, Section
from .bench_mqtt import _mosquitto
from .bench_opcua import _start_drives, opcua_section

__all__ = [
    "CONFIGURATIONS",
    "TITLE",
    "USES_EVENT_LOOP",
    "Child",
    "main",
    "measure",
    "report",
    "run",
]

TITLE = "plant"
USES_EVENT_LOOP = True
#: Each configuration's northbounds, in the order they run.
CONFIGURATIONS: Final = (
    *("bare", "mqtt", "sparkplug", "mqtt+sparkplug", "opcua", "http", "modbus", "all"),
)
#: The northbounds of ``all``.
EVERY: Final = frozenset({"mqtt", "sparkplug", "opcua", "http", "modbus"})
LINES: Final = 64
DRIVES_PER_LINE: Final = 32
QUICK_LINES: Final = 2
QUICK_DRIVES_PER_LINE: Final = 4
INTERVAL_S: Final = 1.0
WARM_UP_S: Final = 12.0
WINDOW_S: Final = 5.0
WINDOWS: Final = 3
QUICK_WARM_UP_S: Final = 2.0
QUICK_WINDOW_S: Final = 1.0
#: Lines per Modbus listener (unit ids 1..224 within each).
LINES_PER_LISTENER: Final = 7
#: The issue's goal: every northbound together at most 2x the poll's CPU per sample.
TARGET_ALL: Final = 1 / 2
#: How long a child may take, over its windows and warm-up.
CHILD_TIMEOUT_S: Final = 300.0


def _toml(which: str, lines: int, per_line: int, broker: int, directory: Path) -> str:
    parts = EVERY if which == "all" else set(which.split("+")) - {"bare"}
    text = '[gateway]\nid = "plant"\n'
    if parts & {"mqtt", "sparkplug"}:
        text += f'[mqtt]\nurl = "mqtt://127.0.0.1:{broker}"\n'
        if "sparkplug" in parts:
            text += 'sparkplug = true\ngroup_id = "plant"\n'
        if "mqtt" not in parts:
            text += "state_topics = false\n"
    if "modbus" in parts:
        text += "[modbus]\n"
        for first in range(0, lines, LINES_PER_LISTENER):
            names = ", ".join(
                f'"l{i}"' for i in range(first, min(lines, first + LINES_PER_LISTENER))
            )
            text += f'[[modbus.listeners]]\nlisten = "127.0.0.1:0"\nlines = [{names}]\n'
    if "opcua" in parts:
        text += opcua_section(directory)
    if "http" in parts:
        text += '[http]\nlisten = "127.0.0.1:0"\n'
    for index in range(lines):
        text += textwrap.dedent(
            f"""
            [[lines]]
            name = "l{index}"
            url = "sim://?nodes=1-{per_line}"
            nodes = "1-{per_line}"
            unit_offset = {(index % LINES_PER_LISTENER) * DRIVES_PER_LINE}
            interval_s = {INTERVAL_S!r}
            trips_interval_s = 0
            setpoint_interval_s = 0
            """
        )
    return text


# -- the child ------------------------------------------------------------------------------


async def _child(args: argparse.Namespace) -> dict[str, Any]:
    from sj300_async.gateway import Gateway, parse_config

    directory = Path(args.directory)
    text = _toml(args.which, args.lines, args.per_line, args.broker, directory)
    loop = asyncio.get_running_loop()
    began = loop.time()
    async with Gateway(parse_config(text, "bench_plant.toml")) as gateway:
        started_s = loop.time() - began
        samples = 0

        def on_sample(sample: Any) -> None:
            nonlocal samples
            samples += 1

        for line in gateway.lines:
            line.poller.on_sample(on_sample)
        await _start_drives(gateway)  # the OPC UA benchmark's ramp: 50 Hz over 300 s
        drives = len(gateway.drives)
        mqtt: Any = gateway.northbounds.get("mqtt")
        parts = getattr(mqtt, "parts", (mqtt,) if mqtt is not None else ())
        bridge = next((p for p in parts if type(p).__name__ == "MqttBridge"), None)
        edge = next((p for p in parts if type(p).__name__ == "EdgeNode"), None)
        visible: dict[str, float] = {}
        deadline = loop.time() + args.warm_up
        while loop.time() < deadline:
            now = loop.time() - began
            if bridge is not None and len(bridge.stats.states) == drives:
                visible.setdefault("mqtt", now)
            if edge is not None and edge.stats.published["DBIRTH"] >= drives:
                visible.setdefault("sparkplug", now)
            await asyncio.sleep(0.05)
        before = _delivery(bridge, edge)
        windows = []
        for _ in range(args.windows):
            cpu, count, wall = time.process_time(), samples, loop.time()
            await asyncio.sleep(args.window)
            cpu, count = time.process_time() - cpu, samples - count
            windows.append({"cpu_s": cpu, "samples": count, "wall_s": loop.time() - wall})
        after = _delivery(bridge, edge)
        statm = Path("/proc/self/statm").read_text(encoding="ascii").split()
        opcua: Any = gateway.northbounds.get("opcua")
        return {
            "which": args.which,
            "drives": drives,
            "started_s": started_s,
            "opcua_startup_s": None if opcua is None else opcua.startup_s,
            "visible_s": visible,
            "windows": windows,
            "rss_bytes": int(statm[1]) * os.sysconf("SC_PAGE_SIZE"),
            "delivery": {k: after[k] - before[k] for k in after},
        }


def _delivery(bridge: Any, edge: Any) -> dict[str, int]:
    """What the MQTT clients did with the samples so far (counters)."""
    out = {"mqtt_samples": 0, "mqtt_states": 0, "mqtt_replaced": 0, "mqtt_lost": 0}
    out |= {"spb_samples": 0, "spb_replaced": 0}
    if bridge is not None:
        stats = bridge.stats
        out["mqtt_samples"] = sum(stats.samples.values())
        out["mqtt_states"] = sum(stats.states.values())
        out["mqtt_replaced"] = sum(stats.replaced.values())
        out["mqtt_lost"] = stats.lost
    if edge is not None:
        out["spb_samples"] = edge.stats.samples
        out["spb_replaced"] = edge.stats.replaced
    return out


def main(argv: Sequence[str] | None = None) -> None:
    """``python -m benchmarks.bench_plant gateway ...``: one configuration's child."""
    parser = argparse.ArgumentParser(prog="python -m benchmarks.bench_plant")
    parser.add_argument("role", choices=["gateway"])
    parser.add_argument("--with", dest="which", choices=CONFIGURATIONS, required=True)
    parser.add_argument("--lines", type=int, default=LINES)
    parser.add_argument("--per-line", type=int, default=DRIVES_PER_LINE)
    parser.add_argument("--broker", type=int, default=0)
    parser.add_argument("--directory", required=True)
    parser.add_argument("--warm-up", type=float, default=WARM_UP_S)
    parser.add_argument("--window", type=float, default=WINDOW_S)
    parser.add_argument("--windows", type=int, default=WINDOWS)
    args = parser.parse_args(argv)
    print(json.dumps(asyncio.run(_child(args))), flush=True)


# -- the parent -----------------------------------------------------------------------------


@dataclass(frozen=True)
class Child:
    """One configuration's figures."""

    which: str
    drives: int
    #: CPU per sample of each window (s).
    cpu_per_sample_s: tuple[float, ...]
    samples_per_s: tuple[float, ...]
    rss_bytes: int
    started_s: float
    opcua_startup_s: float | None
    visible_s: dict[str, float]
    delivery: dict[str, int]

    @property
    def best_cpu_s(self) -> float:
        return min(self.cpu_per_sample_s)

    @classmethod
    def from_json(cls, body: dict[str, Any]) -> Child:
        windows = body["windows"]
        return cls(
            which=body["which"],
            drives=body["drives"],
            cpu_per_sample_s=tuple(w["cpu_s"] / max(1, w["samples"]) for w in windows),
            samples_per_s=tuple(w["samples"] / w["wall_s"] for w in windows),
            rss_bytes=body["rss_bytes"],
            started_s=body["started_s"],
            opcua_startup_s=body["opcua_startup_s"],
            visible_s=body["visible_s"],
            delivery=body["delivery"],
        )


def _run_child(which: str, config: Config, broker: int, directory: Path) -> Child:
    quick = config.quick
    command = [
        sys.executable, "-m", "benchmarks.bench_plant", "gateway", "--with", which,
        "--broker", str(broker), "--directory", str(directory),
        "--lines", str(QUICK_LINES if quick else LINES),
        "--per-line", str(QUICK_DRIVES_PER_LINE if quick else DRIVES_PER_LINE),
        "--warm-up", str(QUICK_WARM_UP_S if quick else WARM_UP_S),
        "--window", str(QUICK_WINDOW_S if quick else WINDOW_S),
        "--windows", str(1 if quick else WINDOWS),
    ]  # fmt: skip
    done = subprocess.run(
        command,
        capture_output=True,
        text=True,
        timeout=CHILD_TIMEOUT_S,
        cwd=Path(__file__).resolve().parent.parent,
        check=False,
    )
    if done.returncode != 0:
        raise RuntimeError(f"the {which} child failed ({done.returncode}): {done.stderr[-2000:]}")
    return Child.from_json(json.loads(done.stdout.strip().splitlines()[-1]))


@contextmanager
def _broker() -> Any:
    with _mosquitto() as port:
        yield port


def measure(config: Config) -> dict[str, Child]:
    """Every configuration's child, one after the other."""
    out: dict[str, Child] = {}
    with _broker() as port, tempfile.TemporaryDirectory(prefix="bench_plant_") as directory:
        for which in ("bare", "all") if config.quick else CONFIGURATIONS:
            out[which] = _run_child(which, config, port, Path(directory))
    return out


def _share(delivered: int, samples: int) -> float:
    return delivered / samples if samples else math.nan


def run(config: Config) -> Section:
    """Measure each configuration; rows against the bare poll of the same run."""
    return report(measure(config))


def report(children: dict[str, Child]) -> Section:
    """The rows and notes of *children*'s figures."""
    bare = children["bare"]
    us = 1e6
    drives = bare.drives
    results = [
        Result(
            f"plant: every northbound, CPU per drive sample ({drives} drives at 1 Hz)",
            children["all"].best_cpu_s * us,
            bare.best_cpu_s * us,
            "µs",
            target=TARGET_ALL,
            higher_is_better=False,
            against="bare poll",
            as_multiple=True,
        )
    ]
    for which in (w for w in CONFIGURATIONS[1:-1] if w in children):
        results.append(
            Result(
                f"plant: {which} alone, CPU per drive sample",
                children[which].best_cpu_s * us,
                bare.best_cpu_s * us,
                "µs",
                higher_is_better=False,
                against="bare poll",
                as_multiple=True,
            )
        )
    whole = children["all"].delivery
    results += [
        Result(
            # Not the states confirmed in the window: up to a chunk of 256 is in flight
            # at each edge of it. A state is failed only by being replaced or lost.
            "plant: JSON states neither replaced nor lost, every northbound on",
            _share(
                whole["mqtt_samples"] - whole["mqtt_replaced"] - whole["mqtt_lost"],
                whole["mqtt_samples"],
            ),
            1.0,
            "share",
            target=1.0,
            against="every sample",
            percent=True,
        ),
        Result(
            "plant: Sparkplug samples not replaced, every northbound on",
            _share(whole["spb_samples"] - whole["spb_replaced"], whole["spb_samples"]),
            1.0,
            "share",
            target=1.0,
            against="every sample",
            percent=True,
        ),
        Result(
            "plant: RSS per drive, every northbound on",
            children["all"].rss_bytes / drives / 1024,
            bare.rss_bytes / drives / 1024,
            "KiB",
            higher_is_better=False,
            against="bare poll",
            as_multiple=True,
        ),
    ]
    notes = [
        f"{drives} simulated SJ300 drives ({len(children)} children, one after the "
        "other), polled every second, each running on a long ramp; CPU per sample is "
        "`process_time` over samples, the best of each child's windows (simulators included, "
        "alike on every side).",
    ]
    for name, child in children.items():
        windows = ", ".join(f"{c * us:.0f}" for c in child.cpu_per_sample_s)
        rates = ", ".join(f"{r:.0f}" for r in child.samples_per_s)
        visible = ", ".join(f"{k} {v:.1f} s" for k, v in sorted(child.visible_s.items()))
        startup = (
            ""
            if child.opcua_startup_s is None
            else f"; OPC UA start-up {child.opcua_startup_s:.1f} s"
        )
        delivery = child.delivery
        notes.append(
            f"`{name}`: CPU per sample by window {windows} µs; samples/s {rates}; RSS "
            f"{child.rss_bytes / 2**20:.0f} MiB ({child.rss_bytes / drives / 1024:.0f} KiB per "
            f"drive); started in {child.started_s:.1f} s{startup}"
            + (f"; every drive visible: {visible}" if visible else "")
            + (f"; JSON states {delivery['mqtt_states']} of {delivery['mqtt_samples']} samples "
               f"confirmed ({delivery['mqtt_replaced']} replaced, {delivery['mqtt_lost']} lost)"
               if delivery["mqtt_samples"] else "")
            + (f"; Sparkplug {delivery['spb_replaced']} of {delivery['spb_samples']} samples "
               "replaced" if delivery["spb_samples"] else "")
        )  # fmt: skip
    return Section(TITLE, tuple(notes), tuple(results))


if __name__ == "__main__":
    main()
