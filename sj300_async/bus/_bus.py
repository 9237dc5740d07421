"""The Bus: one line, its link, its arbiter, and the drives on it.

A bus speaks one protocol, its dialect, and knows nothing else of it:
:meth:`Bus.drive` hands out whatever drive object the dialect makes, and
:attr:`Bus.broadcast` its every-drive object (or refuses when the protocol
has none). For type checkers the bus is generic in the two:
``sj300_async.open_bus(url)`` gives a ``Bus[Drive, Broadcast]``,
``open_bus(url, protocol="fr700")`` a ``Bus[Fr700Drive, None]``. A plain
``Bus`` is ``Bus[Any, Any]``.

The drives talk to the arbiter through a :class:`~._channel.Channel` typed
in their protocol's request type; the bus itself only stores the dialect,
so it holds it as ``Dialect[Any, Any]``: the types are checked where the
requests are built and answered, not where they are stored.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Callable
from typing import Any, Generic, Literal, cast

from typing_extensions import TypeVar

from ..transports import SerialSettingsError
from ..wire import BusClosedError, LineSettings, LocalProtocolError, TransportError
from ._arbiter import Arbiter
from ._capture import combine
from ._channel import Channel
from ._chunklog import ChunkLog
from ._dialect import Dialect
from ._link import Connector, Link, ReconnectPolicy
from ._protocol import LineProtocol
from ._registry import DEFAULT_PROTOCOL, get_dialect
from ._stats import BusStats
from ._timing import BusTiming
from ._trace import TraceHook

__all__ = ["BroadcastT", "Bus", "ConnectMode", "DriveT"]

#: The drive class a bus hands out (for type checkers).
DriveT = TypeVar("DriveT", default=Any)
#: The every-drive object a bus hands out (for type checkers).
BroadcastT = TypeVar("BroadcastT", default=Any)

_log = logging.getLogger("sj300_async.bus")

#: How :meth:`Bus.start` treats a first connection that fails: raise (``"now"``)
#: or serve the line as down and reconnect in the background (``"background"``).
ConnectMode = Literal["now", "background"]


class Bus(Generic[DriveT, BroadcastT]):
    """One RS-485 line and the drives on it. Open it with :func:`~sj300_async.open_bus`.

    Attributes:
        stats: counters of the whole bus.
        line: the line settings used for wire-time arithmetic.
        timing: the timing policy.
        retries: attempts after the first for transmission errors and time-outs.
        read_only: refuse every command that changes a drive.
        dialect: the protocol spoken on this bus.
        simulator: the simulated line behind a ``sim://`` bus (None otherwise):
            tests use its fault hooks, demos trip its drives.

    ``capture`` is a trace hook of its own (a line of a
    :class:`~._capture.CaptureFile`): it sees every frame whatever
    :attr:`trace` is set to later.
    """

    def __init__(
        self,
        connector: Connector,
        *,
        description: str,
        line: LineSettings,
        timing: BusTiming,
        dialect: Dialect[Any, Any] | None = None,
        retries: int = 2,
        strip_echo: bool | None = None,
        read_only: bool = False,
        trace: TraceHook | None = None,
        reconnect: ReconnectPolicy | None = None,
        capture: TraceHook | None = None,
    ) -> None:
        if isinstance(retries, bool) or not isinstance(retries, int) or retries < 0:
            raise LocalProtocolError(f"retries must be an int >= 0, got {retries!r}")
        self.description = description
        self.stats = BusStats()
        self.line = line
        self.timing = timing
        self.retries = retries
        self.read_only = read_only
        if dialect is None:
            dialect = get_dialect(DEFAULT_PROTOCOL)
        self.dialect = dialect
        self._trace = trace
        # The capture sees every frame whatever the trace hook is set to later.
        self._capture = capture
        self._recorder: ChunkLog | None = None
        self._strip_echo = strip_echo
        self._parser = dialect.new_parser()
        self.link = Link(
            connector, self._make_protocol, self.stats, description=description, policy=reconnect
        )
        self._arbiter = Arbiter(self.link, line, timing, self.stats, dialect)
        self.channel = Channel(self, self._arbiter, dialect, retries)
        self._drives: dict[int, DriveT] = {}
        self._broadcast = cast(BroadcastT, dialect.make_broadcast(self.channel))
        self._closed = False
        self.simulator: Any = None
        self._supervisor: asyncio.Task[None] | None = None

    def _make_protocol(self) -> LineProtocol[Any]:
        # A new connection starts with a clean parser: bytes of the old one are gone.
        self._parser.reset()
        return LineProtocol(
            self._parser,
            self._arbiter,
            self.stats,
            strip_echo=self._strip_echo,
            trace=combine(self._trace, self._capture),
            recorder=self._recorder,
        )

    @property
    def trace(self) -> TraceHook | None:
        """The hook that sees every frame; set it to None to stop tracing."""
        return self._trace

    @trace.setter
    def trace(self, hook: TraceHook | None) -> None:
        self._trace = hook
        protocol = self.link.protocol
        if protocol is not None:
            protocol.trace = combine(hook, self._capture)

    @property
    def recorder(self) -> ChunkLog | None:
        """Where every chunk written and received is kept (None: nowhere).

        A trace hook sees a record of each chunk with the frames it completed;
        a recorder keeps only the chunk, its time and whether an answer in it
        came too early, for a fraction of the cost (every chunk of every line
        passes here): the workbench keeps each line's recent traffic so.
        """
        return self._recorder

    @recorder.setter
    def recorder(self, log: ChunkLog | None) -> None:
        self._recorder = log
        protocol = self.link.protocol
        if protocol is not None:
            protocol.recorder = log

    @property
    def connected(self) -> bool:
        """True while the link is up."""
        return self.link.connected

    def on_connected(self, callback: Callable[[], None]) -> Callable[[], None]:
        """Call *callback* each time the link comes up, before any request can go; returns
        what unregisters it (see :meth:`Link.on_connected <._link.Link.on_connected>`)."""
        return self.link.on_connected(callback)

    @property
    def closed(self) -> bool:
        """True once the bus is closed."""
        return self._closed

    def drive(self, node: int, *, wait_time_s: float | None = None) -> DriveT:
        """Return the drive at *node* (the same object each time).

        Args:
            wait_time_s: the drive's own wait before replying in seconds, if
                known (SJ300: C078; FR-700: Pr.123 when requests carry no
                waiting-time field).

        Raises:
            LocalProtocolError: *node* is out of the protocol's range.
        """
        # Validate before the cache: True == 1 and 1.0 == 1 would find drive 1.
        if isinstance(node, bool) or not isinstance(node, int):
            low, high = self.dialect.node_range
            raise LocalProtocolError(
                f"a {self.dialect.node_noun} must be an int {low}..{high}, got {node!r}"
            )
        drive = self._drives.get(node)
        if drive is None:
            # The dialect makes the protocol's drive class; open_bus's overloads
            # tie DriveT to the protocol.
            drive = cast(DriveT, self.dialect.make_drive(self.channel, node))
            self._drives[node] = drive
        if wait_time_s is not None:
            if not 0 <= wait_time_s <= 1.0:
                raise LocalProtocolError(f"a drive's wait time is 0..1 s, got {wait_time_s!r}")
            cast(Any, drive).wait_time_s = wait_time_s
        return drive

    @property
    def drives(self) -> dict[int, DriveT]:
        """The drives handed out so far, by node."""
        return dict(self._drives)

    @property
    def broadcast(self) -> BroadcastT:
        """Commands to every drive at once (no reply).

        Raises:
            LocalProtocolError: the bus's protocol has no broadcast (FR-700).
        """
        if self._broadcast is None:
            raise LocalProtocolError(f"the {self.dialect.name} protocol has no broadcast")
        return self._broadcast

    async def start(self, *, connect: ConnectMode = "now") -> None:
        """Connect, and keep the link up from now on (``open_bus`` calls this).

        Args:
            connect: ``"now"`` (the default) raises when the first attempt
                fails; ``"background"`` makes the same one attempt, and when
                the line is down (refused, timed out, unreachable, a serial
                device that is not there) returns with the link down and
                leaves it to the reconnect supervisor, as for a link lost
                later: requests fail at once with :class:`TransportError`
                until it connects. :attr:`connected` and
                :attr:`Link.last_error` tell which. A port that refuses the
                line settings (:class:`~sj300_async.transports.SerialSettingsError`)
                will refuse them every time: it raises either way.

        The reconnect supervisor is a plain task owned by the bus, not an anyio
        task group held across ``open_bus``'s yield: a task group would wrap
        the caller's own exceptions (a NakError raised in the body) in an
        ExceptionGroup.

        Raises:
            TransportError: the first connection failed (``connect="now"``),
                or the port refused the line settings.
            LocalProtocolError: *connect* is neither mode.
        """
        if connect not in ("now", "background"):
            raise LocalProtocolError(f'connect must be "now" or "background", got {connect!r}')
        try:
            await self.link.connect()
        except (SerialSettingsError, BusClosedError):  # never better on a later attempt
            raise
        except TransportError as exc:
            if connect == "now":
                raise
            _log.info("%s; retrying in the background", exc)
        self._supervisor = asyncio.create_task(
            self.link.supervise(), name=f"sj300 link {self.description}"
        )

    def close(self) -> None:
        """Close the bus: the link closes, waiting requests fail. Idempotent."""
        self._closed = True
        self.link.close()
        self._arbiter.close()
        if self._supervisor is not None:
            self._supervisor.cancel()

    async def aclose(self) -> None:
        """Close the bus and wait until its background task has ended. Idempotent."""
        self.close()
        supervisor, self._supervisor = self._supervisor, None
        if supervisor is not None:
            # wait() neither raises the supervisor's CancelledError nor hides ours.
            await asyncio.wait([supervisor])
            if not supervisor.cancelled() and supervisor.exception() is not None:
                _log.error("link supervisor failed", exc_info=supervisor.exception())

    async def __aenter__(self) -> Bus[DriveT, BroadcastT]:
        await self.start()
        return self

    async def __aexit__(self, *exc_info: object) -> None:
        await self.aclose()
