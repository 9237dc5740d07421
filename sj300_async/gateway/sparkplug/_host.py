"""The primary host application's STATE, read: online, offline, or a message that changes nothing.

Sans-IO. With a ``primary_host_id``, the edge node subscribes to
``spBv1.0/STATE/<host>`` and is born only while the host's latest STATE
says ``online: true`` (Sparkplug 3.0, section 5.5). A STATE is JSON,
``{"online": bool, "timestamp": int}``; one older (its timestamp) than the
one already seen is stale and ignored, since anyone may publish a STATE and
the broker may deliver a retained one late. What is read is kept over a new
connection only as the order of timestamps: the host's word counts on the
connection it came on (:meth:`PrimaryHost.forget`).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from typing import Final

from .. import excerpt

__all__ = ["MAX_STATE_BYTES", "HostWord", "PrimaryHost", "Unread"]

#: The longest STATE read (a real one is some 50 bytes of JSON).
MAX_STATE_BYTES: Final = 1024


@dataclass(frozen=True, slots=True)
class Unread:
    """A STATE that changes nothing: why (a ``BAD_INPUTS`` label) and what it was."""

    reason: str
    text: str


@dataclass(frozen=True, slots=True)
class HostWord:
    """A STATE taken: the host is online or not, and whether it said so already."""

    online: bool
    #: The previous word was the same (online again: no news for the log).
    again: bool


class PrimaryHost:
    """One primary host's STATE, as the edge node last read it."""

    def __init__(self, host_id: str, namespace: str) -> None:
        self.id = host_id
        self.topic = f"{namespace}/STATE/{host_id}"
        #: The host's latest word on this connection (None: none yet).
        self.online: bool | None = None
        self._stamp: int | None = None

    def forget(self) -> None:
        """A new connection: the host has said nothing on it yet (the order stays)."""
        self.online = None

    def read(self, payload: bytes, length: int) -> HostWord | Unread:
        """Take a STATE of *length* bytes (*payload*: what was read of it)."""
        if length > MAX_STATE_BYTES:
            return Unread("oversized", f"STATE: {length} bytes, not read")
        try:
            body = json.loads(payload)
            online, stamp = body["online"], body["timestamp"]
            if (
                not isinstance(online, bool)
                or not isinstance(stamp, int)
                or isinstance(stamp, bool)
            ):
                raise TypeError
        except (ValueError, TypeError, KeyError, RecursionError):  # '[' * 3000 recurses
            return Unread("malformed", f"STATE {excerpt(payload)!r}")
        if self._stamp is not None and stamp < self._stamp:
            return Unread("stale_state", f"STATE of {stamp} after one of {self._stamp}")
        self._stamp = stamp
        was, self.online = self.online, online
        return HostWord(online, again=was is online)
