"""The audit log: every write, refused or not, whichever northbound it came through.

One line per write at INFO on the ``sj300_async.gateway.audit`` logger
(``client 10.0.0.9 line hall node 1 (unit 1): parameter A004 50.0 -> 60.0:
ok``) and, when a file is configured, one JSON object per line appended to
it (flushed each time: an audit log that loses its last lines in a crash is
not one). A refusal's ``result`` is ``refused``, with the neutral reason
(:class:`~._writes.Refusal`'s value) and the sentence saying why.

Untrusted text (an MQTT payload, a topic) reaches a log, an error reply or
this file only as a short escaped excerpt (:func:`excerpt`), never whole:
every northbound uses it, and :meth:`AuditLog.record` applies it once more
to every value it writes (a text ``old`` or ``new``, ``what``, the detail),
so no client can make a log line longer than a few hundred characters.
"""

from __future__ import annotations

import collections
import json
import logging
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Final

from ._drive import GatewayDrive
from ._writes import WriteResult

__all__ = ["AuditLog", "excerpt"]

_audit_log = logging.getLogger("sj300_async.gateway.audit")

#: The longest excerpt of a client's text kept in a log line or an error reply.
EXCERPT_CHARS: Final = 64
#: The longest sentence (a refusal's detail) the audit log keeps: ours, but it
#: may quote a client's text.
_DETAIL_CHARS: Final = 256
#: The most values of a sequence (a Modbus write's registers) the audit log keeps whole.
_MAX_VALUES: Final = 125


def excerpt(text: str | bytes, limit: int = EXCERPT_CHARS, *, size: int | None = None) -> str:
    """At most *limit* characters of a client's *text*, safe to log, show or store.

    Unprintable characters are escaped (``\\x1b``, ``\\n``; bytes that are not
    UTF-8 become U+FFFD), and a text that does not fit is cut where a
    character starts, its size noted: ``run_forw…(1048576 bytes)`` (counted
    in characters for a ``str``). Only the head of *text* is read, whatever
    its size. *size*: the whole text's, when *text* is only its head (a
    payload too long to read).
    """
    size = len(text) if size is None else size
    head = text[: 4 * limit]  # enough for limit characters: UTF-8 takes at most 4 bytes each
    if isinstance(head, bytes):
        head, unit = head.decode("utf-8", errors="replace"), "bytes"
    else:
        unit = "characters"
    shown = [c if c.isprintable() else repr(c)[1:-1] for c in head[: limit + 1]]
    if size <= 4 * limit and len(head) <= limit and sum(map(len, shown)) <= limit:
        return "".join(shown)
    note = f"…({size} {unit})"
    budget, out = limit - len(note), []
    for piece in shown:
        budget -= len(piece)
        if budget < 0:
            break
        out.append(piece)
    return "".join(out) + note


#: Records the audit log keeps in memory (the file, when configured, keeps them all).
RECENT: Final = 1000


class AuditLog:
    """Every write: who, which drive, what, old -> new, and the result (module docstring)."""

    def __init__(self, path: Path | None = None) -> None:
        self.path = path
        self._file = None if path is None else path.open("a", encoding="utf-8")
        #: The latest records, newest last, as the file has them (the workbench's audit
        #: page): bounded, so a gateway that runs for years holds :data:`RECENT` at most.
        self.recent: collections.deque[dict[str, object]] = collections.deque(maxlen=RECENT)
        #: Records written, by result: ``"ok"``, a refusal's reason, or a lapse's outcome.
        self.counts: dict[str, int] = {}

    def write(
        self,
        client: str,
        drive: GatewayDrive,
        what: str,
        old: object,
        new: object,
        result: WriteResult,
    ) -> None:
        """Record a write's result."""
        if result.refusal is None:
            self.record(client, drive, what, old, new, "ok", count_as="ok")
            return
        self.record(
            client,
            drive,
            what,
            old,
            new,
            f"refused: {result}",
            count_as=result.refusal.value,
            fields={"reason": result.refusal.value, "detail": result.detail},
        )

    def record(
        self,
        client: str,
        drive: GatewayDrive,
        what: str,
        old: object,
        new: object,
        result: str,
        *,
        count_as: str | None = None,
        fields: dict[str, object] | None = None,
    ) -> None:
        """Record one line: *result* as the log shows it, counted as *count_as* (default it)."""
        key = result if count_as is None else count_as
        self.counts[key] = self.counts.get(key, 0) + 1
        line, node, unit = drive.line.name, drive.node, drive.unit
        # Whatever a caller passes, nothing a client sent is written whole (module docstring).
        what, old, new = excerpt(what), _value(old), _value(new)
        result = excerpt(result, _DETAIL_CHARS)
        if fields is not None:
            fields = {name: _value(value, _DETAIL_CHARS) for name, value in fields.items()}
        _audit_log.info(
            "client %s line %s node %d (unit %d): %s %s -> %s: %s",
            client, line, node, unit, what, old, new, result,
        )  # fmt: skip
        entry: dict[str, object] = {
            "time": time.time(),
            "client": client,
            "line": line,
            "node": node,
            "unit": unit,
            "what": what,
            "old": old,
            "new": new,
            "result": "refused" if fields is not None else result,
        }
        if fields is not None:
            entry |= fields
        self.recent.append(entry)
        if self._file is not None:
            self._file.write(json.dumps(entry) + "\n")
            self._file.flush()

    def close(self) -> None:
        if self._file is not None:
            self._file.close()
            self._file = None


def _value(value: object, limit: int = EXCERPT_CHARS) -> object:
    """*value* as the audit log keeps it: a number as it is, text (or anything else) excerpted."""
    if value is None or isinstance(value, bool | int | float):
        return value
    if (
        isinstance(value, Sequence)
        and not isinstance(value, str | bytes)
        and len(value) <= _MAX_VALUES
        and all(isinstance(item, int | float) for item in value)
    ):
        return list(value)  # a Modbus write's registers: a JSON array
    return excerpt(value if isinstance(value, str | bytes) else str(value), limit)
