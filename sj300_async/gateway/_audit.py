"""The audit log: every write, refused or not, whichever northbound it came through.

One line per write at INFO on the ``sj300_async.gateway.audit`` logger
(``client 10.0.0.9 line hall node 1 (unit 1): parameter A004 50.0 -> 60.0:
ok``) and, when a file is configured, one JSON object per line appended to
it (flushed each time: an audit log that loses its last lines in a crash is
not one). A refusal's ``result`` is ``refused``, with the neutral reason
(:class:`~._writes.Refusal`'s value) and the sentence saying why.

Untrusted text (an MQTT payload) reaches the log as a short escaped
excerpt (:func:`excerpt`), never whole.
"""

from __future__ import annotations

import json
import logging
import time
from pathlib import Path
from typing import Final

from ._drive import GatewayDrive
from ._writes import WriteResult

__all__ = ["AuditLog", "excerpt"]

_audit_log = logging.getLogger("sj300_async.gateway.audit")

#: The longest excerpt of a client's text kept in a log line or an error reply.
EXCERPT_CHARS: Final = 64


def excerpt(text: str, limit: int = EXCERPT_CHARS) -> str:
    """*text* with unprintable characters escaped, cut to *limit* characters (``…`` marks a cut)."""
    escaped = "".join(c if c.isprintable() else repr(c)[1:-1] for c in text[: limit + 1])
    return escaped if len(escaped) <= limit else escaped[: limit - 1] + "…"


class AuditLog:
    """Every write: who, which drive, what, old -> new, and the result (module docstring)."""

    def __init__(self, path: Path | None = None) -> None:
        self.path = path
        self._file = None if path is None else path.open("a", encoding="utf-8")
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
        _audit_log.info(
            "client %s line %s node %d (unit %d): %s %s -> %s: %s",
            client, line, node, unit, what, old, new, result,
        )  # fmt: skip
        if self._file is not None:
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
            self._file.write(json.dumps(entry) + "\n")
            self._file.flush()

    def close(self) -> None:
        if self._file is not None:
            self._file.close()
            self._file = None
