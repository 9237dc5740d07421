"""The whole gateway for a long time: its memory and its descriptors stay flat (issue 44).

One gateway process of the plant benchmark's ``all`` configuration
(:mod:`benchmarks._soak`, ``python -m benchmarks.bench_plant soak``): every
northbound with its clients (MQTT with discovery and Sparkplug on a real
mosquitto, an OPC UA subscription on every drive, two workbench event
streams, a Modbus master per listener reading the summary), the simulated
drives swinging on their ramps so that every poll changes every output. Its
resident set and open descriptors are read from ``/proc`` every
``gateway_sample_s`` seconds, from outside the process.

**The long form** (``make soak``): 8 lines of 32 drives polled every 0.1 s
(2,560 samples a second asked, about 1,700 kept up on 2 cores: a drive's
hours at 1 Hz compressed) for 30 minutes, a sample a minute. After the first
5 minutes (the rings fill: each line's traffic log reaches its 50,000 chunks
in about a minute, and the workbench's trends, 2 minutes of samples in this
soak, in about 4: benchmarks/_soak.py says why not the default 15) the RSS
must stay within 1 % of its value at 5 minutes at every sample, and the open
descriptors must not change at all.

**The short form** (every ``pytest``, CI): 2 lines of 16 drives at 0.1 s for
30 s, a sample every 3 s, judged from 12 s on. It must stay well under a
minute of wall time, so it cannot see a steady state: a ring that fills for
minutes is still filling at 30 s. What it asserts honestly:

- the open descriptors are flat from 12 s on (a connection, a file or a
  socket leaked per request or per reconnect shows at once);
- the gateway still delivers: samples, JSON states and Sparkplug DDATA in
  every 3-s interval, and every client receiving at the end;
- the RSS stays within :data:`SHORT_BUDGET_KIB` (4 MiB) above its value at
  12 s, at every sample. The budget is what may still fill in those 18 s,
  with room: the line-traffic log of the 2 lines (each 160 samples a second,
  two transactions each: 640 chunks a second of 35 bytes on average plus 12
  of bookkeeping, some 1.1 MiB in 18 s for both, less once its older
  segments are compacted), the workbench's trends (32 drives, 10 samples a
  second, 16 bytes each before a block is packed: 90 KiB in 18 s), and the
  allocator's arenas moving (the first runs' RSS went up and down by up to
  0.6 MiB from one sample to the next). A leak of 1 KiB per drive sample
  (5,760 samples in those 18 s: 5.6 MiB) fails it; a slow leak, bytes per
  sample, is what the long form is for.

``SJ300_GATEWAY_SOAK_S`` and ``SJ300_GATEWAY_SOAK_SETTLE_S`` override the
run's and the settling's seconds (a shortened long form, to check that it
runs; the published figures are the defaults').
"""

from __future__ import annotations

import os
import time
from dataclasses import replace
from typing import Any, Final

import pytest

from benchmarks._soak import CHECK_S, Sample, Soak, fds_flat, run_soak, verdict

from .rel_sizes import Sizes

pytestmark = pytest.mark.soak

#: The long form's bound: the RSS after settling stays within this share of it.
LONG_MAX_GROWTH_PCT: Final = 1.0
#: The short form's bound above its RSS at settling, KiB (the module docstring).
SHORT_BUDGET_KIB: Final = 4 * 1024


def _sized(sizes: Sizes) -> Sizes:
    """*sizes* with the environment's overrides of the run's and the settling's seconds."""
    run = os.environ.get("SJ300_GATEWAY_SOAK_S")
    settle = os.environ.get("SJ300_GATEWAY_SOAK_SETTLE_S")
    if run is not None:
        sizes = replace(sizes, gateway_soak_s=float(run))
    if settle is not None:
        sizes = replace(sizes, gateway_settle_s=float(settle))
    return sizes


def _figures(soak: Soak, elapsed_s: float) -> dict[str, Any]:
    clients = soak.clients.get("clients", {})
    return {
        "plant": f"{soak.lines} x {soak.per_line} drives at {soak.interval_s:g} s",
        "soak_s": soak.duration_s,
        "settle_s": soak.settle_s,
        "ready_s": round(soak.ready_s, 1),
        "series": [
            {
                "t_s": round(s.t_s),
                "rss_mib": round(s.rss_kib / 1024, 1),
                "fds": s.fds,
                "samples_per_s": round(s.samples_per_s),
                "cpu_share": round(s.cpu_share, 2),
            }
            for s in soak.series
        ],
        "verdict": soak.verdict,
        # the headlines (tests/conftest.py): the largest growth above settling, fds min/max
        "rss_peak_growth_pct": round(soak.verdict.get("peak_growth_pct", float("nan")), 2),
        "fds_after_settle": [soak.verdict.get("fds_min"), soak.verdict.get("fds_max")],
        "clients_at_the_end": {
            name: one.get("messages", one.get("reads")) for name, one in clients.items()
        },
        "mqtt_lost": soak.mqtt_lost,
        "swing_write_errors": soak.swing_errors,
        "elapsed_s": round(elapsed_s, 1),
    }


def test_gateway_soak_keeps_memory_and_descriptors_flat(
    sizes: Sizes, soak: bool, soak_figures: dict[str, Any]
) -> None:
    sized = _sized(sizes)
    began = time.perf_counter()
    run = run_soak(
        lines=sized.gateway_lines,
        per_line=sized.gateway_drives_per_line,
        interval_s=sized.gateway_interval_s,
        duration_s=sized.gateway_soak_s,
        sample_every_s=sized.gateway_sample_s,
        settle_s=sized.gateway_settle_s,
        check_s=CHECK_S,
    )
    soak_figures["gateway_soak"] = _figures(run, time.perf_counter() - began)
    held = run.verdict
    assert held["problems"] == [], "the gateway must still deliver, every interval and at the end"
    assert fds_flat(held), [s.fds for s in run.series]  # never above the steady count
    series = [(round(s.t_s), s.rss_kib) for s in run.series]
    if soak:
        assert held["peak_growth_pct"] < LONG_MAX_GROWTH_PCT, series
    else:
        assert held["peak_growth_kib"] < SHORT_BUDGET_KIB, series


def _series(*rows: tuple[float, int, int, float]) -> tuple[Sample, ...]:
    return tuple(Sample(t, rss, fds, rate, rate, rate, 0.5) for t, rss, fds, rate in rows)


def test_the_verdict_fails_a_stalled_gateway_and_measures_from_settling() -> None:
    clients = {
        "clients": {
            **{name: {"messages": 10, "failure": None} for name in ("mqtt", "sparkplug", "opcua")},
            "http": {"messages": 20, "failure": None},
            "modbus": {"reads": 4, "errors": {}, "failure": None},
        }
    }
    soak = Soak(2, 16, 0.1, 30.0, 12.0, 120.0, 1.0, 2.0, (), clients, None, 0, 0)
    flat = _series((0, 90_000, 17, 0), (6, 99_000, 18, 320), (12, 100_000, 17, 320),
                   (18, 100_500, 17, 320), (30, 100_200, 17, 320))  # fmt: skip
    held = verdict(replace(soak, series=flat))
    assert held["problems"] == []
    assert (held["rss_at_settle_kib"], held["growth_kib"], held["peak_growth_kib"]) == (
        100_000, 200, 500,
    )  # fmt: skip
    assert (held["fds_min"], held["fds_max"]) == (17, 17)  # the warm-up's 18 is not counted
    assert held["fds_steady"] == 17
    assert fds_flat(held)
    # a client reconnecting: fewer for a moment, never more (not a leak)
    dip = (*flat[:3], replace(flat[3], fds=14), flat[4])
    assert fds_flat(verdict(replace(soak, series=dip)))
    # a leak: each sample more than the one before
    leak = (*flat[:3], replace(flat[3], fds=18), replace(flat[4], fds=19))
    held = verdict(replace(soak, series=leak))
    assert held["fds_steady"] == 17
    assert not fds_flat(held)
    # a dip at settling is not the steady count
    late = (*flat[:2], replace(flat[2], fds=14), flat[3], flat[4])
    assert fds_flat(verdict(replace(soak, series=late)))
    # memory flat for the wrong reason: the poll stopped for an interval
    stalled = (*flat[:3], Sample(18, 100_000, 17, 0.0, 320, 320, 0.0), flat[4])
    assert verdict(replace(soak, series=stalled))["problems"] == [
        "no samples in the interval to 18 s"
    ]
    # a client that got nothing at the end
    silent = {"clients": {**clients["clients"], "opcua": {"messages": 0, "failure": None}}}
    problems = verdict(replace(soak, series=flat, clients=silent))["problems"]
    assert len(problems) == 1
    assert problems[0].startswith("opcua's client received nothing")
