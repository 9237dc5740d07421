"""The simulator as the benchmarks' load: drives that answer at once, and what they cost.

The in-memory benchmarks run the simulated drives in the same process as the
stack, so the process's time includes the simulator's. To report the
library's own share, :func:`simulator_cost` times the simulator's sans-IO
core (:meth:`SimulatedBus.receive`: parse the request, run the drive model,
encode the reply) alone on the same requests, and the benchmarks subtract
it. What the subtraction leaves in "ours" although it belongs to the
simulator: the endpoint that schedules each reply on the event loop (a timer
handle and a heap entry per reply). So the library's share is, if anything,
overstated.
"""

from __future__ import annotations

import time
from collections.abc import Iterable, Sequence

from sj300_async.simulator.sj300 import SimulatedBus
from sj300_async.sj300 import Request

__all__ = ["instant_simulator", "simulator_cost"]


def instant_simulator(nodes: Iterable[int]) -> SimulatedBus:
    """Drives at *nodes* that answer without the emulated 1 ms processing time.

    ``DEFAULT_PROCESSING_S`` (1 ms) emulates a real drive; with it, an
    in-memory benchmark would time the emulated drive's wait, not the stack.
    """
    return SimulatedBus(nodes=nodes, processing_s=0.0)


def simulator_cost(
    requests: Sequence[Request], rounds: int, nodes: Iterable[int] | None = None
) -> float:
    """Seconds :meth:`SimulatedBus.receive` takes for one of *requests*, at best.

    A fresh simulator (at *nodes*, default the requests' nodes) answers every
    request *rounds* times; the fastest round's mean per request is returned,
    the same estimator as the benchmarks' best-of runs, so that the share
    subtracted from a best run is the simulator's best too. Time advances
    between calls as it would on a live line, since the drive model
    integrates ramps and hour counters over it.

    Raises:
        RuntimeError: a request got no reply (the simulator is not the load it should be).
    """
    sim = instant_simulator(sorted(set(nodes or (r.node for r in requests))))
    frames = [r.frame for r in requests]
    per_round: list[float] = []  # mean seconds per request, one entry per round
    for _ in range(rounds):
        start = time.perf_counter()
        for frame in frames:
            if not sim.receive(frame, time.perf_counter()):
                raise RuntimeError(f"the simulator did not answer {frame!r}")
        per_round.append((time.perf_counter() - start) / len(frames))
    return min(per_round)
