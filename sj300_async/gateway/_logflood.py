"""Log floods stopped at the source: N like records per interval, then one line counting the rest.

A client that sends garbage must not turn it into log volume: asyncua logs
a traceback for each malformed chunk (2,000 chunks gave 2.7 MB of log in
issue 41's probe), aiohttp one for each request a handler failed, and a
flood of them costs the event loop the formatting and the disk the bytes.
While a gateway runs, :class:`FloodLimit` sits on every logger of the
gateway's own package and of the libraries its doors use
(:data:`LIMITED_PREFIXES`) and lets through at most :data:`PER_INTERVAL`
records of one kind per :data:`INTERVAL_S`; the rest are dropped before
any handler formats them, counted per logger
(``sj300_gateway_log_suppressed_total``), and announced in one WARNING
line when their interval ends: how many, and the first one's message.

Decisions:

- **A library's record's kind is its logger and call site** (logger
  name, level, file, line): the same ``logger.exception`` in a loop is one
  kind whatever its arguments. **Ours are limited when identical** (the
  same call site and message): a lapse on each of 32 drives is 32 kinds,
  a refusal repeated for one client is one.
- **Our own DEBUG lines are not limited.** They are opt-in (``-vv``), each
  is a bounded excerpt, and the doors count what they refuse; a test or an
  engineer reading them wants every one. Everything else is.
- **Filters sit on loggers, not handlers.** The handlers are the
  application's (``sj300 gateway -v``, systemd's journal, an embedding
  service's own); a logger's filter runs before any of them, Python's
  fallback handler included. A filter on a logger does not see its
  children's records, so :func:`install` puts one on every logger under
  the prefixes and :meth:`FloodLimit.flush` (called each second by the
  gateway's loop monitor) adds it to loggers created since.
- **Process-wide, as logging is.** Installed when the first gateway of the
  process starts and removed when the last one stops, so a library user's
  process outside a gateway keeps logging exactly as configured.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import TYPE_CHECKING, Final

if TYPE_CHECKING:
    from prometheus_client.core import Metric

__all__ = [
    "INTERVAL_S",
    "LIMITED_PREFIXES",
    "PER_INTERVAL",
    "FloodLimit",
    "install",
    "installed",
    "uninstall",
]

#: Records of one kind let through per interval, and the interval.
PER_INTERVAL: Final = 5
INTERVAL_S: Final = 10.0
#: The loggers limited: the gateway's own and its doors' libraries'.
LIMITED_PREFIXES: Final = ("sj300_async", "asyncua", "aiohttp", "asyncio", "aiomqtt")
#: Kinds of record tracked at most (past it, the oldest window is forgotten).
MAX_KINDS: Final = 1024

_OWN: Final = "sj300_async"
_log = logging.getLogger("sj300_async.gateway.logs")


@dataclass(slots=True)
class _Window:
    start: float
    passed: int = 0
    suppressed: int = 0
    #: The first suppressed record's logger and message (for the summary line).
    logger: str = ""
    message: str = ""


def _message(record: logging.LogRecord) -> str:
    try:
        return record.getMessage()
    except Exception:  # a record whose arguments do not fit its message
        return str(record.msg)


class FloodLimit(logging.Filter):
    """The filter (see the module docstring)."""

    def __init__(
        self,
        per_interval: int = PER_INTERVAL,
        interval_s: float = INTERVAL_S,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        super().__init__()
        self.per_interval = per_interval
        self.interval_s = interval_s
        self._clock = clock
        self._windows: dict[tuple[str, int, str, int, str], _Window] = {}
        #: Records suppressed since the start, by logger name.
        self.suppressed: dict[str, int] = {}

    def filter(self, record: logging.LogRecord) -> bool:
        if record.levelno <= logging.DEBUG and record.name.startswith(_OWN):
            return True
        own = record.name.startswith(_OWN)
        key = (record.name, record.levelno, record.pathname, record.lineno,
               _message(record) if own else "")  # fmt: skip
        now = self._clock()
        window = self._windows.get(key)
        if window is None or now >= window.start + self.interval_s:
            if window is not None:
                self._announce(window)
            window = self._windows[key] = _Window(now)
            while len(self._windows) > MAX_KINDS:
                self._announce(self._windows.pop(next(iter(self._windows))))
        if window.passed < self.per_interval:
            window.passed += 1
            return True
        if not window.suppressed:
            window.logger = record.name
            window.message = (key[4] or _message(record))[:200]
        window.suppressed += 1
        self.suppressed[record.name] = self.suppressed.get(record.name, 0) + 1
        return False

    def flush(self) -> None:
        """Announce the windows that ended; put the filter on loggers created since."""
        now = self._clock()
        ended = [key for key, w in self._windows.items() if now >= w.start + self.interval_s]
        for key in ended:
            self._announce(self._windows.pop(key))
        if self is _installed:  # a limit taken off stays off, whoever still holds it
            _attach(self)

    def _announce(self, window: _Window) -> None:
        if window.suppressed:
            _log.warning(
                "%d more log records like this one from %s suppressed in %g s: %s",
                window.suppressed,
                window.logger,
                self.interval_s,
                window.message,
            )

    def metrics(self) -> Iterator[Metric]:
        from prometheus_client.core import CounterMetricFamily

        family = CounterMetricFamily(
            "sj300_gateway_log_suppressed",
            "Log records dropped by the flood limit (like records past "
            f"{self.per_interval} per {self.interval_s:g} s; each interval announced in one line).",
            labels=["logger"],
        )
        for name, count in sorted(self.suppressed.items()):
            family.add_metric([name], count)
        yield family


def _limited_loggers() -> Iterator[logging.Logger]:
    for prefix in LIMITED_PREFIXES:
        yield logging.getLogger(prefix)
    for name, logger in list(logging.Logger.manager.loggerDict.items()):
        if isinstance(logger, logging.Logger) and name.startswith(LIMITED_PREFIXES):
            yield logger


def _attach(limit: FloodLimit) -> None:
    for logger in _limited_loggers():
        if limit not in logger.filters:
            logger.addFilter(limit)


_installed: FloodLimit | None = None
_users = 0


def install() -> FloodLimit:
    """The process's flood limit, installed on its loggers (counted: :func:`uninstall`)."""
    global _installed, _users
    if _installed is None:
        _take_off_every_limit()  # none may be on the loggers now: a fresh start
        _installed = FloodLimit()
    _users += 1
    _attach(_installed)
    return _installed


def installed() -> FloodLimit | None:
    """The flood limit in force, or None."""
    return _installed


def uninstall() -> None:
    """One user fewer; the last one takes the filter off every logger."""
    global _installed, _users
    _users = max(0, _users - 1)
    if _users or _installed is None:
        return
    limit, _installed = _installed, None
    windows, limit._windows = limit._windows, {}
    for window in windows.values():  # announcing logs, which may add a window
        limit._announce(window)
    _take_off_every_limit()


def _take_off_every_limit() -> None:
    """Every flood limit off every logger, not only the installed one: one left on a logger
    (a full test suite once found one there after the last gateway stopped) would outlive
    every gateway, swallowing a process's repeated lines with no gateway to say so."""
    for logger in _limited_loggers():
        for stale in [f for f in logger.filters if isinstance(f, FloodLimit)]:
            logger.removeFilter(stale)
