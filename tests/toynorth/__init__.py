"""A fourth northbound, defined entirely inside the tests: "jsonl", a JSON-lines writer.

It proves that adding a way of serving the drives is one package plus one
registry entry, with no library file touched:
:func:`sj300_async.gateway.register_northbound` is the entry
(``register_northbound("jsonl", "toynorth:NORTHBOUND")``), this package the
northbound. It imports only the public faces of :mod:`sj300_async.gateway`
and :mod:`sj300_async.profiles` (and prometheus-client, for its one metric
family, when the gateway's /metrics is scraped).

- Its configuration section: ``[jsonl] path = "states.jsonl"``, a file in
  an existing directory (relative: to the configuration file's directory),
  validated through :class:`~sj300_async.gateway.ConfigTable` so that its
  errors name the file, line and key like every other.
- Its command-line flag: ``--jsonl PATH`` sets ``jsonl.path``.
- Running: it appends one JSON object per drive snapshot the gateway hands
  it (after each poll, each write's read-back, each trip-history read),
  flushed at once, and counts them (``toynorth_jsonl_lines_total`` on the
  gateway's /metrics).
"""

from __future__ import annotations

import json
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import IO, TYPE_CHECKING, Any, Final

from sj300_async.gateway import (
    ConfigTable,
    Endpoint,
    Flag,
    GatewayView,
    Northbound,
    SectionContext,
    ServedDrive,
)
from sj300_async.profiles import DriveSnapshot

if TYPE_CHECKING:
    from prometheus_client.core import Metric

__all__ = ["NORTHBOUND", "JsonlConfig", "JsonlNorthbound", "snapshot_json"]

#: The metric family it contributes (``_total`` is added by the exposition).
LINES_FAMILY: Final = "toynorth_jsonl_lines"


@dataclass(frozen=True, slots=True)
class JsonlConfig:
    """``[jsonl]``: the file the snapshots are appended to."""

    path: Path


def snapshot_json(gateway: str, snapshot: DriveSnapshot) -> dict[str, Any]:
    """One line of the file: a drive's snapshot, in neutral terms."""
    direction = snapshot.direction
    return {
        "gateway": gateway,
        "line": snapshot.line,
        "node": snapshot.node,
        "unit": snapshot.unit,
        "protocol": snapshot.protocol,
        "time": snapshot.time,
        "online": snapshot.online,
        "available": snapshot.available,
        "state": snapshot.state,
        "running": snapshot.running,
        "tripped": snapshot.tripped,
        "direction": None if direction is None else direction.name.lower(),
        "output_frequency_hz": snapshot.output_frequency_hz,
        "output_current_a": snapshot.output_current_a,
        "set_frequency_hz": snapshot.set_frequency_hz,
        "parameters": {code: p.value for code, p in snapshot.parameters.items()},
    }


class JsonlNorthbound:
    """Appends each snapshot to the file (a :class:`~sj300_async.gateway.Northbound`)."""

    def __init__(self, config: JsonlConfig) -> None:
        self.config = config
        #: Lines written so far.
        self.lines = 0
        self._gateway = ""
        self._file: IO[str] | None = None

    async def start(self, gateway: GatewayView) -> None:
        self._gateway = gateway.config.gateway_id
        self._file = self.config.path.open("a", encoding="utf-8")

    def announce(self) -> str | None:
        return f"jsonl to {self.config.path}"

    def publish(self, served: ServedDrive) -> None:
        snapshot = served.snapshot
        if self._file is None:
            return
        self._file.write(json.dumps(snapshot_json(self._gateway, snapshot)) + "\n")
        self.lines += 1

    def flush(self) -> None:
        """The gateway's batch is whole: to the file with it (one write for the batch)."""
        if self._file is not None:
            self._file.flush()

    def metrics(self) -> Iterator[Metric]:
        from prometheus_client.core import CounterMetricFamily

        family = CounterMetricFamily(LINES_FAMILY, "Snapshots written to the JSON-lines file.")
        family.add_metric([], self.lines)
        yield family

    async def close(self) -> None:
        if self._file is not None:
            self._file.close()
            self._file = None


class _Spec:
    section = "jsonl"
    keys = ("path",)
    flag = Flag("--jsonl", "path", "PATH", "append one JSON object per drive snapshot to PATH")
    requires: Sequence[str] = ()

    def parse(self, table: ConfigTable, context: SectionContext) -> JsonlConfig:
        text = table.required_string("path")
        if not text.strip():
            raise table.error("path", "expected a file name, got an empty string")
        path = context.base_dir / text  # an absolute path stays as it is
        if path.is_dir():
            raise table.error("path", f"{str(path)!r} is a directory")
        if not path.parent.is_dir():
            raise table.error("path", f"no such directory: {str(path.parent)!r}")
        return JsonlConfig(path)

    def endpoints(self, config: object) -> Sequence[tuple[str, Endpoint]]:
        return ()  # a file: it listens on nothing

    def create(self, config: object) -> Northbound:
        assert isinstance(config, JsonlConfig)
        return JsonlNorthbound(config)


#: The registry's entry (``toynorth:NORTHBOUND``).
NORTHBOUND: Final = _Spec()
