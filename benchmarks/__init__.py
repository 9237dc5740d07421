"""Benchmarks of sj300_async against pymodbus, measured in the same run.

Run them all with ``python -m benchmarks`` from the repository root
(``--quick`` for a smoke run, ``--only NAME`` for one of :data:`BENCHMARKS`,
``--uvloop`` to run those that use an event loop once more on uvloop).

Each benchmark is a module with ``TITLE``, ``USES_EVENT_LOOP`` and
``run(config) -> Section`` (see :mod:`benchmarks._harness`); add a new one by
writing the module and naming it in :data:`BENCHMARKS`. Modules are imported
only when chosen.
"""

from __future__ import annotations

import importlib
from typing import Protocol

from ._harness import Config, Section

__all__ = ["BENCHMARKS", "Benchmark", "load"]

#: name -> module, in the order they run and print.
BENCHMARKS: dict[str, str] = {
    "codec": "benchmarks.bench_codec",
    "tcp": "benchmarks.bench_tcp",
    "loopback": "benchmarks.bench_loopback",
    "latency": "benchmarks.bench_latency",
    "wire": "benchmarks.bench_wire",
    "scale": "benchmarks.bench_scale",
    "gateway": "benchmarks.bench_gateway",
    "mqtt": "benchmarks.bench_mqtt",
    "workbench": "benchmarks.bench_workbench",
    "opcua": "benchmarks.bench_opcua",
    "plant": "benchmarks.bench_plant",
    "attack": "benchmarks.bench_attack",
}


class Benchmark(Protocol):
    """What a benchmark module provides."""

    TITLE: str
    #: True when it runs an event loop: ``--uvloop`` reruns it on uvloop.
    USES_EVENT_LOOP: bool

    def run(self, config: Config) -> Section:
        """Measure ours and the peer; return the rows and the notes that describe the input."""
        ...


def load(name: str) -> Benchmark:
    """Import the benchmark called *name*.

    Raises:
        KeyError: no benchmark has that name.
    """
    module: Benchmark = importlib.import_module(BENCHMARKS[name])
    return module
