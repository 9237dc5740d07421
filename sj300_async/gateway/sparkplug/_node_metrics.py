"""The edge node's own metrics: its session's, and each line's health, in NBIRTH and NDATA.

``bdSeq`` and ``Node Control/Rebirth`` (no alias: a host looks them up by
name), then :data:`NODE_METRICS` for each line under ``Lines/<line>/``,
aliased 1, 2, ... in the configuration's order (below 65536: the devices'
aliases start there, :mod:`._device`). The edge node checks the lines'
values once a second and sends those that changed as NDATA.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from typing import Final

from .. import ServedLine
from ._payload import BOOLEAN, INT64, UINT32, UINT64, MetricDef

__all__ = ["NODE_METRICS", "REBIRTH", "SESSION_METRICS", "node_definitions", "node_values"]

REBIRTH: Final = "Node Control/Rebirth"
#: The metrics before the lines' (bdSeq, Rebirth): never in an NDATA.
SESSION_METRICS: Final = 2
#: Each line's metrics in the NBIRTH: (name under ``Lines/<line>/``, datatype).
NODE_METRICS: Final = (
    ("Connected", BOOLEAN),
    ("Drives Online", UINT32),
    ("Timeouts", UINT64),
    ("Transport Errors", UINT64),
)


def node_definitions(lines: Sequence[ServedLine]) -> list[MetricDef]:
    """The edge node's metrics for *lines*, ``bdSeq`` first (the NDEATH carries it alone)."""
    definitions = [MetricDef("bdSeq", None, INT64), MetricDef(REBIRTH, None, BOOLEAN)]
    aliases = iter(range(1, 1 + len(lines) * len(NODE_METRICS)))
    for line in lines:
        for name, datatype in NODE_METRICS:
            definitions.append(
                MetricDef(f"Lines/{line.config.name}/{name}", next(aliases), datatype)
            )
    return definitions


def node_values(bdseq: int, lines: Sequence[ServedLine]) -> list[object]:
    """The values of :func:`node_definitions` now (Rebirth is always false)."""
    values: list[object] = [bdseq, False]
    for line in lines:
        values.extend(_line_values(line))
    return values


def _line_values(line: ServedLine) -> Iterator[object]:
    """A line's :data:`NODE_METRICS` values now (the core's health of the line)."""
    health = line.health()
    yield health.connected
    yield health.drives_online
    yield health.timeouts
    yield health.transport_errors
