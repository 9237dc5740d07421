"""The ``[recorder]`` section: where trip records are kept, what each covers, how many.

Decisions:

- **On by default.** A gateway keeps a record of every trip unless
  ``enabled = false``: the seconds before a trip are the ones nobody
  thought to keep.
- **Where.** ``directory`` is taken relative to the configuration file's
  directory; without it, ``trips`` under systemd's ``$STATE_DIRECTORY``
  when set (the unit's ``StateDirectory=``: under ``ProtectSystem=strict``
  the configuration's directory is read-only), else ``trips`` beside the
  file. A gateway without a configuration file (flags, ``--demo``) keeps
  its records in memory, bounded the same way, and loses them when it
  stops.
- **What a record covers.** ``before_s`` (60) before the trip and
  ``after_s`` (10) after it; the drive's trend is sized to cover both.
- **How many.** At most ``max_records`` (1,000) and ``max_bytes``
  (256 MiB, JSON and pcapng together), the oldest pruned first: an edge
  box's disk is not the recorder's to fill.
- A configuration given as text (``parse_config``, not ``load_config``)
  is no file: its records are kept in memory unless it names a
  ``directory`` (taken relative to its source's directory).
- A reload keeps the recorder as it was (its settings are said as needing
  a restart): the trends it sized and the records pending belong to it.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Final

if TYPE_CHECKING:  # _model imports this module, and _toml imports _model
    from .._toml import ConfigTable

__all__ = [
    "DEFAULT_AFTER_S",
    "DEFAULT_BEFORE_S",
    "DEFAULT_MAX_BYTES",
    "DEFAULT_MAX_RECORDS",
    "RECORDER_KEYS",
    "RecorderConfig",
    "parse_recorder",
]

DEFAULT_BEFORE_S: Final = 60.0
DEFAULT_AFTER_S: Final = 10.0
DEFAULT_MAX_RECORDS: Final = 1000
DEFAULT_MAX_BYTES: Final = 256 * 1024 * 1024
#: The most seconds a record may cover on either side: a trend and a line log are kept
#: that long for every drive, so the bound is the memory's.
LONGEST_S: Final = 3600.0
RECORDER_KEYS: Final = ("enabled", "directory", "before_s", "after_s", "max_records",
                        "max_bytes")  # fmt: skip


@dataclass(frozen=True, slots=True)
class RecorderConfig:
    """The trip recorder's settings (see the module docstring)."""

    enabled: bool = True
    #: Where the records are kept; None: in memory (no configuration file).
    directory: Path | None = None
    before_s: float = DEFAULT_BEFORE_S
    after_s: float = DEFAULT_AFTER_S
    max_records: int = DEFAULT_MAX_RECORDS
    max_bytes: int = DEFAULT_MAX_BYTES

    @property
    def window_s(self) -> float:
        """Seconds of each drive's samples a record needs kept (0: off)."""
        return self.before_s + self.after_s if self.enabled else 0.0


def parse_recorder(
    table: ConfigTable | None, base_dir: Path, state_dir: Path | None, *, file: bool
) -> RecorderConfig:
    """The ``[recorder]`` *table* (None: not given) of a configuration whose directory
    is *base_dir*; *file*: it was read from a file (else, without a ``directory``, the
    records are kept in memory)."""
    text = None if table is None else table.string("directory")
    if table is not None and text is not None and not text.strip():
        raise table.error("directory", "expected a directory, got an empty string")
    if text is not None:
        directory: Path | None = base_dir / text  # an absolute path stays as it is
    elif file:
        directory = (state_dir or base_dir) / "trips"
    else:
        directory = None  # flags, --demo, a text: memory
    if table is None:
        return RecorderConfig(directory=directory)
    enabled = table.boolean("enabled")
    return RecorderConfig(
        enabled=True if enabled is None else enabled,
        directory=directory,
        before_s=_seconds(table, "before_s", DEFAULT_BEFORE_S),
        after_s=_seconds(table, "after_s", DEFAULT_AFTER_S),
        max_records=_count(table, "max_records", DEFAULT_MAX_RECORDS),
        max_bytes=_count(table, "max_bytes", DEFAULT_MAX_BYTES),
    )


def _seconds(table: ConfigTable, key: str, default: float) -> float:
    value = table.number(key, minimum=0, inclusive=True)
    if value is None:
        return default
    if value > LONGEST_S:
        raise table.error(key, f"at most {LONGEST_S:g} s, got {value:g}")
    return value


def _count(table: ConfigTable, key: str, default: int) -> int:
    value = table.integer(key)
    if value is None:
        return default
    if value < 1:
        raise table.error(key, f"expected at least 1, got {value}")
    return value
