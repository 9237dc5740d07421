"""Where trip records are kept: a directory (one JSON and one pcapng each), or memory.

Decisions:

- **Atomic, the JSON last.** Each file is written under a temporary name
  beside its place, flushed to the disk and renamed over it; the pcapng
  first, then the JSON. A record is its JSON: a crash between the two
  leaves a pcapng no record names (named at the next start, left alone),
  never a record whose frames are half written.
- **Off the loop, one at a time.** Every read and write of a file runs in a
  thread (``asyncio.to_thread``), behind one lock: the poll shares the loop,
  and a plant whose drives all trip at once (a mains dip) queues its
  records rather than starting a thread per drive.
- **Known from memory.** At start every record's JSON is read once (in a
  thread) into a small summary (:class:`RecordSummary`): listing is from
  memory, only a record asked for is read again. A file that is not a
  record (not JSON, not the record's shape, a name that is not its id) is
  skipped and named in one log line, never fatal; the rest are served.
- **Bounded.** After each record the oldest go until at most
  ``max_records`` remain and their bytes (JSON and pcapng) are within
  ``max_bytes``; the newest is kept whatever its size.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import os
import re
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Final

from .._fastjson import compact_json
from ._settings import RecorderConfig

__all__ = ["FORMAT", "RECORD_ID", "RecordSummary", "TripStore"]

_log = logging.getLogger("sj300_async.gateway.recorder")

#: A record's ``format``: what a file must say to be read as one.
FORMAT: Final = "sj300-trip-record"
#: What a record id looks like: its trip's UTC time, its line and its node.
RECORD_ID: Final = re.compile(r"[0-9]{8}T[0-9]{6}\.[0-9]{3}Z-[A-Za-z0-9_.-]{1,64}-[0-9]{1,3}")
#: Damaged files named by name in the start's log line; the rest are counted.
_NAMED: Final = 10


@dataclass(frozen=True, slots=True)
class RecordSummary:
    """What a list of records shows of one (the record's JSON holds the rest)."""

    id: str
    line: str
    node: int
    protocol: str
    #: The trip's Unix time.
    time: float
    code: str | None
    meaning: str | None
    #: What saw the trip: ``"poll"`` (the status) or ``"trip history"``.
    seen_by: str
    #: Its files' bytes, JSON and pcapng.
    size: int

    def as_json(self) -> dict[str, Any]:
        return {
            "id": self.id,
            "line": self.line,
            "node": self.node,
            "protocol": self.protocol,
            "time": self.time,
            "code": self.code,
            "meaning": self.meaning,
            "seen_by": self.seen_by,
            "bytes": self.size,
        }


def summary_of(record: object, size: int) -> RecordSummary:
    """The summary of a record's parsed JSON.

    Raises:
        ValueError: it is not a record (its format, a key missing or of a wrong type).
    """
    if not isinstance(record, dict) or record.get("format") != FORMAT:
        raise ValueError(f"not a {FORMAT}")
    trip = record.get("trip")
    trip = trip if isinstance(trip, dict) else {}
    try:
        summary = RecordSummary(
            id=_typed(record, "id", str),
            line=_typed(record, "line", str),
            node=_typed(record, "node", int),
            protocol=_typed(record, "protocol", str),
            time=float(_typed(record, "time", (int, float))),
            code=_optional(trip.get("code")),
            meaning=_optional(trip.get("meaning")),
            seen_by=_typed(record, "seen_by", str),
            size=size,
        )
    except (KeyError, TypeError) as exc:
        raise ValueError(str(exc)) from None
    if not RECORD_ID.fullmatch(summary.id):
        raise ValueError(f"id {summary.id[:80]!r} is not a record's")
    return summary


def _typed(record: dict[str, Any], key: str, kind: type | tuple[type, ...]) -> Any:
    value = record[key]
    if isinstance(value, bool) or not isinstance(value, kind):
        raise TypeError(f"{key}: expected {kind}, got {type(value).__name__}")
    return value


def _optional(value: object) -> str | None:
    return value if isinstance(value, str) else None


class TripStore:
    """The records kept (see the module docstring): in *config*'s directory, or memory."""

    def __init__(self, config: RecorderConfig) -> None:
        self.directory = config.directory
        self.max_records = config.max_records
        self.max_bytes = config.max_bytes
        #: Every record's summary, oldest first.
        self._summaries: dict[str, RecordSummary] = {}
        #: The records themselves, when kept in memory: (JSON, pcapng) by id.
        self._memory: dict[str, tuple[bytes, bytes]] = {}
        self._lock = asyncio.Lock()
        #: Records written, pruned, failed to write; damaged files skipped at start.
        self.counts: dict[str, int] = {"written": 0, "pruned": 0, "failed": 0, "damaged": 0}

    @property
    def in_memory(self) -> bool:
        return self.directory is None

    def __len__(self) -> int:
        return len(self._summaries)

    @property
    def size(self) -> int:
        """The bytes every record takes, JSON and pcapng."""
        return sum(s.size for s in self._summaries.values())

    def summaries(self, line: str | None = None, node: int | None = None) -> list[RecordSummary]:
        """The records of *line* (and *node*; every one when None), newest first."""
        found = [
            s
            for s in self._summaries.values()
            if (line is None or s.line == line) and (node is None or s.node == node)
        ]
        found.sort(key=lambda s: (s.time, s.id), reverse=True)
        return found

    def summary(self, record_id: str) -> RecordSummary | None:
        return self._summaries.get(record_id)

    async def load(self) -> None:
        """Read what the directory holds (nothing to do in memory). Never raises for a
        file: a damaged one is skipped and named in the log."""
        if self.directory is None:
            return
        async with self._lock:
            found, damaged = await asyncio.to_thread(_scan, self.directory)
        for summary in sorted(found, key=lambda s: (s.time, s.id)):
            self._summaries[summary.id] = summary
        self.counts["damaged"] += len(damaged)
        if damaged:
            named = ", ".join(damaged[:_NAMED])
            more = f" and {len(damaged) - _NAMED} more" if len(damaged) > _NAMED else ""
            _log.warning("trip records: skipped %d damaged file(s) in %s: %s%s",
                         len(damaged), self.directory, named, more)  # fmt: skip
        await self._prune()

    async def add(self, record: dict[str, Any], frames: bytes) -> RecordSummary | None:
        """Keep *record* (its JSON's value) and its *frames* (pcapng); prune the oldest.
        None (logged, counted) when the files could not be written."""
        data = await asyncio.to_thread(compact_json, record)
        summary = summary_of(record, len(data) + len(frames))
        async with self._lock:
            if self.directory is None:
                self._memory[summary.id] = (data, frames)
            else:
                try:
                    await asyncio.to_thread(_write, self.directory, summary.id, data, frames)
                except OSError as exc:
                    self.counts["failed"] += 1
                    _log.error("trip record %s not written to %s: %s",
                               summary.id, self.directory, exc)  # fmt: skip
                    return None
            self._summaries[summary.id] = summary
            self.counts["written"] += 1
        await self._prune()
        return summary

    async def read(self, record_id: str) -> bytes | None:
        """The record's JSON as kept, None when there is no such record (or its file is
        gone or unreadable since: logged)."""
        return await self._file(record_id, 0, ".json")

    async def frames(self, record_id: str) -> bytes | None:
        """The record's pcapng, None when there is no such record or file."""
        return await self._file(record_id, 1, ".pcapng")

    async def _file(self, record_id: str, which: int, suffix: str) -> bytes | None:
        if record_id not in self._summaries:
            return None
        if self.directory is None:
            kept = self._memory.get(record_id)
            return None if kept is None else kept[which]
        path = self.directory / f"{record_id}{suffix}"
        try:
            return await asyncio.to_thread(path.read_bytes)
        except OSError as exc:
            _log.warning("trip record %s: %s cannot be read: %s", record_id, path, exc)
            return None

    async def _prune(self) -> None:
        async with self._lock:  # chosen and counted under the lock: each record once
            going: list[str] = []
            ids = list(self._summaries)  # oldest first
            total = self.size
            while len(ids) - len(going) > 1 and (
                len(ids) - len(going) > self.max_records or total > self.max_bytes
            ):
                oldest = ids[len(going)]
                going.append(oldest)
                total -= self._summaries[oldest].size
            if not going:
                return
            for record_id in going:
                del self._summaries[record_id]
                self._memory.pop(record_id, None)
            if self.directory is not None:
                await asyncio.to_thread(_remove, self.directory, going)
            self.counts["pruned"] += len(going)
        _log.debug("trip records: pruned %d, the oldest (%s)", len(going), going[0])


# -- in a thread ---------------------------------------------------------------------------


def _scan(directory: Path) -> tuple[list[RecordSummary], list[str]]:
    """Every record in *directory*, and the names of the files that are not one."""
    if not directory.is_dir():
        return [], []
    import orjson

    found: list[RecordSummary] = []
    damaged: list[str] = []
    names = {entry.name for entry in os.scandir(directory)}
    for name in sorted(names):
        if name.startswith(".") and name.endswith(".tmp"):  # a write that never ended
            with contextlib.suppress(OSError):
                (directory / name).unlink()
            continue
        if not name.endswith(".json"):
            continue
        stem = name[: -len(".json")]
        frames = f"{stem}.pcapng"
        try:
            data = (directory / name).read_bytes()
            summary = summary_of(orjson.loads(data), len(data))
            if summary.id != stem:
                raise ValueError(f"its id is {summary.id!r}")
            if frames not in names:
                raise ValueError(f"{frames} is missing")
            size = len(data) + (directory / frames).stat().st_size
        except (OSError, ValueError) as exc:  # orjson's JSONDecodeError is a ValueError
            damaged.append(f"{name} ({str(exc)[:80]})")
            continue
        found.append(_sized(summary, size))
    for name in sorted(names):  # frames whose JSON was never written (a crash between)
        if name.endswith(".pcapng") and f"{name[: -len('.pcapng')]}.json" not in names:
            damaged.append(f"{name} (no record names it)")
    return found, damaged


def _sized(summary: RecordSummary, size: int) -> RecordSummary:
    return RecordSummary(
        summary.id, summary.line, summary.node, summary.protocol, summary.time,
        summary.code, summary.meaning, summary.seen_by, size,
    )  # fmt: skip


def _write(directory: Path, record_id: str, data: bytes, frames: bytes) -> None:
    directory.mkdir(parents=True, exist_ok=True)
    _atomic(directory / f"{record_id}.pcapng", frames)
    _atomic(directory / f"{record_id}.json", data)
    with contextlib.suppress(OSError):  # the renames, on the disk too (not on every FS)
        fd = os.open(directory, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


def _atomic(path: Path, data: bytes) -> None:
    temporary = path.with_name(f".{path.name}.tmp")
    with contextlib.suppress(FileNotFoundError):  # one left by a write that never ended
        temporary.unlink()
    try:
        # Made new, never through a link planted there (the gateway may run as root).
        fd = os.open(temporary, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW, 0o644)
        with os.fdopen(fd, "wb") as file:
            file.write(data)
            file.flush()
            os.fsync(file.fileno())
        os.replace(temporary, path)
    except BaseException:
        with contextlib.suppress(OSError):
            temporary.unlink()
        raise


def _remove(directory: Path, ids: Iterable[str]) -> None:
    for record_id in ids:
        for suffix in (".json", ".pcapng"):  # the JSON first: no record without its frames
            with contextlib.suppress(FileNotFoundError):
                (directory / f"{record_id}{suffix}").unlink()
