"""The toy protocol's codec, dialect, drive class and simulator (see the package docstring)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

from sj300_async.bus import Channel, TransactionStats, parse_flag
from sj300_async.simulator import Transmission
from sj300_async.wire import (
    BadFrame,
    BadFrameReason,
    Discarded,
    DiscardReason,
    LocalProtocolError,
    NakError,
    ParserStats,
    SJ300Error,
)
from sj300_async.wire._frames import FrameRole, LineFrame

_MAX_LINE = 64


@dataclass(frozen=True, slots=True)
class ToyRequest:
    node: int
    key: str
    value: int | None = None  # None: a read

    @property
    def frame(self) -> bytes:
        if self.value is None:
            return f"?{self.node:02d} R {self.key}\n".encode()
        return f"?{self.node:02d} W {self.key} {self.value}\n".encode()

    @property
    def expects_reply(self) -> bool:
        return True

    @property
    def label(self) -> str:
        return f"{'write' if self.value is not None else 'read'} {self.key}"


@dataclass(frozen=True, slots=True)
class ToyValue:
    node: int
    value: bytes


@dataclass(frozen=True, slots=True)
class ToyOk:
    node: int


@dataclass(frozen=True, slots=True)
class ToyNak:
    node: int
    code: int


ToyReply = ToyValue | ToyOk | ToyNak


class ToyParser:
    """Splits the line at LF; a line that is not a reply is a bad frame."""

    def __init__(self) -> None:
        self._buffer = b""
        self.stats = ParserStats()

    def feed(self, data: bytes) -> list[ToyReply | BadFrame | Discarded]:
        self._buffer += data
        events: list[ToyReply | BadFrame | Discarded] = []
        while b"\n" in self._buffer:
            line, _, self._buffer = self._buffer.partition(b"\n")
            events.append(self._decode(line))
        if len(self._buffer) > _MAX_LINE:
            events.append(Discarded(DiscardReason.OVERLONG, self._buffer))
            self._buffer = b""
        return events

    def reset(self) -> list[Discarded]:
        partial, self._buffer = self._buffer, b""
        return [Discarded(DiscardReason.RESTARTED, partial)] if partial else []

    @staticmethod
    def _decode(line: bytes) -> ToyReply | BadFrame:
        head, _, rest = line.partition(b" ")
        if len(head) != 3 or head[:1] not in (b"!", b"#") or not head[1:].isdigit() or not rest:
            return BadFrame(BadFrameReason.BAD_CHARACTERS, line)
        node = int(head[1:])
        if head[:1] == b"#":
            return (
                ToyNak(node, int(rest))
                if rest.isdigit()
                else BadFrame(BadFrameReason.BAD_CHARACTERS, line, node)
            )
        return ToyOk(node) if rest == b"OK" else ToyValue(node, rest)


class ToyLineFramer:
    """The whole toy line: a piece per LF-ended line, a request starting ``?``, a reply ``!``/``#``.

    A line longer than the longest one is noise, in pieces of that length.
    """

    def __init__(self) -> None:
        self._buffer = b""

    def feed(self, data: bytes) -> list[bytes]:
        self._buffer += data
        pieces: list[bytes] = []
        while True:
            end = self._buffer.find(b"\n", 0, _MAX_LINE + 1)
            if end < 0 and len(self._buffer) <= _MAX_LINE:
                return pieces
            cut = end + 1 if end >= 0 else _MAX_LINE + 1
            pieces.append(self._buffer[:cut])
            self._buffer = self._buffer[cut:]

    def flush(self) -> list[bytes]:
        partial, self._buffer = self._buffer, b""
        return [partial] if partial else []

    def classify(
        self, piece: bytes, *, outbound: bool | None, pending: object | None = None
    ) -> LineFrame:
        line = piece[:-1]
        if not piece.endswith(b"\n") or len(line) > _MAX_LINE:
            return LineFrame(piece, FrameRole.NOISE, None, "not a line", problem="garbage")
        if line.startswith(b"?"):
            parts = line[1:].decode("ascii", "replace").split()
            if len(parts) in (3, 4) and parts[0].isdigit() and parts[1] in ("R", "W"):
                value = int(parts[3]) if len(parts) == 4 and parts[3].isdigit() else None
                request = ToyRequest(int(parts[0]), parts[2], value)
                return LineFrame(
                    piece,
                    FrameRole.REQUEST,
                    request.node,
                    f"unit {request.node}: {request.label}",
                    message=request,
                    expects_reply=True,
                )
            return LineFrame(piece, FrameRole.BROKEN, None, "bad request", problem="bad request")
        reply = ToyParser._decode(line)
        if isinstance(reply, BadFrame):
            return LineFrame(
                piece, FrameRole.BROKEN, reply.node, "bad reply", problem=reply.reason.value
            )
        return LineFrame(piece, FrameRole.REPLY, reply.node, repr(reply), message=reply)


class ToyDrive:
    """A toy device: registers by key."""

    def __init__(self, channel: Channel[ToyRequest], node: int, *, upper: bool) -> None:
        if isinstance(node, bool) or not 1 <= node <= 9:
            raise LocalProtocolError(f"a toy node is 1..9, got {node!r}")
        self.node = node
        self.wait_time_s = 0.0
        self.stats = TransactionStats()
        self._channel = channel
        self._upper = upper

    def _key(self, key: str) -> str:
        return key.upper() if self._upper else key

    async def read(self, key: str) -> int:
        data = await self._channel.transact(ToyRequest(self.node, self._key(key)), self.stats)
        return int(data)

    async def write(self, key: str, value: int) -> None:
        await self._channel.transact(ToyRequest(self.node, self._key(key), value), self.stats)

    async def read_status(self) -> int:
        return await self.read("status")

    async def read_monitor(self) -> int:
        return await self.read("speed")

    async def read_parameter(self, code: str) -> float:
        return float(await self.read(code.removeprefix("toy:")))


class ToyDialect:
    name = "toy"
    node_range = (1, 9)
    node_noun = "unit"
    default_sim_nodes = "1-3"
    url_options = frozenset(("upper",))
    simulator = "toyproto._protocol:simulate"
    profile = "toyproto._profile:TOY_PROFILE"
    capture_linktype = 149  # LINKTYPE_USER2 (docs/CAPTURE.md: free for a third protocol)

    def __init__(self, *, upper: bool = False) -> None:
        self.upper = upper

    def configure(self, options: Mapping[str, str]) -> ToyDialect:
        return ToyDialect(upper=parse_flag("upper", options.get("upper", "0")))

    def new_parser(self) -> ToyParser:
        return ToyParser()

    def answers(self, request: ToyRequest, reply: ToyReply) -> bool:
        if reply.node != request.node:
            return False
        if isinstance(reply, ToyNak):
            return True
        return isinstance(reply, ToyOk) == (request.value is not None)

    def accept(self, request: ToyRequest, reply: ToyReply) -> bytes:
        if isinstance(reply, ToyValue):
            return reply.value
        if isinstance(reply, ToyOk):
            return b""
        raise NakError(reply.node, reply.code, f"unit {reply.node} refused: code {reply.code}")

    def retryable(self, exc: SJ300Error) -> bool:
        return not isinstance(exc, NakError)

    def writes(self, request: ToyRequest) -> bool:
        return request.value is not None

    def reply_frame_length(self, request: ToyRequest) -> int:
        return _MAX_LINE

    def shortest_reply_length(self, request: ToyRequest) -> int:
        return 6  # "#01 2\n" or "!01 5\n"

    def sync_request(self, node: int, pending: Sequence[ToyRequest]) -> ToyRequest | None:
        # Every read is answered by a value, every write by OK: a read can tell
        # the node's late OKs from its answer, but nothing tells a late value
        # from another read's (the arbiter then waits the late replies out).
        if any(request.value is None for request in pending):
            return None
        return ToyRequest(node, "status")

    def processing_s(self, request: ToyRequest) -> float:
        return 0.0

    acknowledges = False

    def acknowledgement(self, request: ToyRequest, reply: ToyReply) -> bytes | None:
        return None

    def answer_delay_s(self) -> float:
        return 0.0

    def rest_after_acknowledgement_s(self) -> float:
        return 0.0

    def reoutput_request(self, request: ToyRequest, bad_frame: BadFrame) -> bytes | None:
        return None

    def line_framer(self) -> ToyLineFramer:
        return ToyLineFramer()

    def describe(self, reply: ToyReply) -> str:
        return repr(reply)

    def parameter_code(self, text: str) -> str | None:
        return text if text.startswith("toy:") else None

    def make_drive(self, channel: Channel[ToyRequest], node: int) -> ToyDrive:
        return ToyDrive(channel, node, upper=self.upper)

    def make_broadcast(self, channel: Channel[ToyRequest]) -> None:
        return None


TOY_DIALECT = ToyDialect()


class ToySimulatedBus:
    """Toy devices on a simulated line: registers in a dict, ``speed`` follows ``set``."""

    protocol = "toy"

    def __init__(self, nodes: tuple[int, ...]) -> None:
        self.registers = {n: {"status": 0, "speed": 0, "set": 0} for n in nodes}
        self.received: list[bytes] = []
        self._buffer = b""

    def receive(self, data: bytes, now: float) -> list[Transmission]:
        self._buffer += data
        out: list[Transmission] = []
        while b"\n" in self._buffer:
            line, _, self._buffer = self._buffer.partition(b"\n")
            self.received.append(line)
            reply = self._answer(line.decode())
            if reply is not None:
                out.append(Transmission(0.0, reply.encode()))
        return out

    def _answer(self, line: str) -> str | None:
        parts = line.split()
        node = int(parts[0][1:])
        registers = self.registers.get(node)
        if registers is None:
            return None  # nobody there: silence
        key = parts[2].lower()
        if key not in registers:
            return f"#{node:02d} 2\n"
        if parts[1] == "R":
            return f"!{node:02d} {registers[key]}\n"
        registers[key] = int(parts[3])
        if key == "set":
            registers["speed"] = registers["status"] = int(parts[3])
        return f"!{node:02d} OK\n"


def simulate(
    dialect: object, nodes: tuple[int, ...], *, factory_defaults: bool, wait_ms: int | None
) -> ToySimulatedBus:
    return ToySimulatedBus(nodes)
