"""Telling systemd how the gateway is: ready, reloading, stopping, alive (``sd_notify``).

A service of ``Type=notify`` is started when it says ``READY=1`` on the
datagram socket systemd names in ``$NOTIFY_SOCKET``; ``sj300 gateway`` says
it once every northbound listens, with a ``STATUS=`` line ``systemctl
status`` shows. With ``WatchdogSec=`` systemd also sets ``$WATCHDOG_USEC``
and restarts a service that has not said ``WATCHDOG=1`` within it.

Decisions:

- **Our own 40 lines, no dependency.** The protocol is one ``sendto`` of
  ``KEY=VALUE`` lines (``sd_notify(3)``); ``systemd-python`` needs
  libsystemd's headers to build, and the pure-Python packages that do this
  are unmaintained.
- **The watchdog is the loop's own probe.** The ping is sent by the loop
  monitor's probe (:mod:`._looplag`), the timer whose lateness is the
  loop-lag measure, every half ``WatchdogSec``: a loop stuck for longer
  than that sends nothing and systemd restarts the gateway; a loop that is
  merely slow (its lag over ``loop_lag_limit_s``, ``/healthz`` degraded)
  still runs the probe and keeps the service, since a restart would drop
  every session and lease for what may pass.
- **Never in the way.** No socket, or one that refuses a datagram: the
  gateway runs on; a refusal is counted and logged at DEBUG, rate-limited
  by the flood guard like every other log line.
"""

from __future__ import annotations

import logging
import os
import socket
from collections.abc import Mapping
from typing import Final

__all__ = ["ServiceManager"]

_log = logging.getLogger("sj300_async.gateway.systemd")

#: The shortest ping interval honoured (a WatchdogSec below 2 s is taken as 2 s).
MIN_PING_S: Final = 1.0


class ServiceManager:
    """The service manager's notification socket (see the module docstring)."""

    def __init__(self, address: str, watchdog_s: float | None = None) -> None:
        #: ``$NOTIFY_SOCKET``: a path, or ``@name`` in the abstract namespace.
        self.address = address
        #: ``$WATCHDOG_USEC`` in seconds, when the watchdog is this process's.
        self.watchdog_s = watchdog_s
        self.sent = 0
        self.failed = 0

    @classmethod
    def from_environment(cls, environ: Mapping[str, str] | None = None) -> ServiceManager | None:
        """The manager that started this process, None when none asked to be told."""
        env = os.environ if environ is None else environ
        address = env.get("NOTIFY_SOCKET", "")
        if not address or address[0] not in "/@":
            return None
        watchdog_s = None
        usec = env.get("WATCHDOG_USEC", "")
        pid = env.get("WATCHDOG_PID", "")
        if usec.isdigit() and int(usec) > 0 and (not pid or pid == str(os.getpid())):
            watchdog_s = int(usec) / 1_000_000
        return cls(address, watchdog_s)

    @property
    def ping_every_s(self) -> float | None:
        """How often to say ``WATCHDOG=1``: half the watchdog's time (None: no watchdog)."""
        return None if self.watchdog_s is None else max(MIN_PING_S, self.watchdog_s / 2)

    def notify(self, *fields: str) -> bool:
        """Send ``KEY=VALUE`` *fields* in one datagram; False when it could not be sent."""
        target = "\0" + self.address[1:] if self.address.startswith("@") else self.address
        data = "\n".join(fields).encode("utf-8", "replace")
        try:
            with socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM) as sock:
                sock.setblocking(False)
                sock.sendto(data, target)
        except OSError as exc:
            self.failed += 1
            _log.debug("systemd: cannot notify %s: %s", self.address, exc)
            return False
        self.sent += 1
        return True

    def ready(self, status: str) -> bool:
        return self.notify("READY=1", f"STATUS={_one_line(status)}")

    def reloading(self) -> bool:
        return self.notify("RELOADING=1", "STATUS=reloading the configuration")

    def stopping(self) -> bool:
        return self.notify("STOPPING=1", "STATUS=stopping")

    def alive(self) -> bool:
        return self.notify("WATCHDOG=1")


def _one_line(text: str) -> str:
    return " ".join(text.split())
