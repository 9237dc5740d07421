"""Line captures: every frame a bus writes and receives, into a pcapng file.

``open_bus(url, capture=PATH)`` (and ``--capture PATH`` on the CLI) writes
a file Wireshark opens; the dissector in ``contrib/wireshark`` decodes it
(docs/CAPTURE.md). A :class:`CaptureFile` holds one interface per line, so
the gateway captures all its lines into one file.

What is a packet. The host writes whole frames: each write is one packet,
outbound. What arrives comes in chunks that need not align with frames, so
the received stream goes through the protocol's line framer
(``Dialect.line_framer()``) and each frame, and each run of bytes outside
a frame, becomes one inbound packet, stamped with the time the chunk that
completed it arrived (the time the host had the whole frame). A frame that
is broken (a wrong check code, a bad length) and noise are captured too,
marked in the packet flags and with a comment. Local echo reaches the host,
so it is captured as it arrived: inbound, in the request's shape.

Cost: nothing unless a capture is open; with one, each chunk is split once
more and each packet is one buffered write (the file is flushed at most
every :data:`FLUSH_EVERY_S` and when it closes).
"""

from __future__ import annotations

import asyncio
import time
from os import PathLike, fspath
from pathlib import Path
from typing import Any, BinaryIO, Final

from ..version import __version__
from ..wire import (
    FLAG_CHECK_ERROR,
    FLAG_NOISE,
    CapturedPacket,
    FrameRole,
    LineFrame,
    LineSettings,
    LocalProtocolError,
    PacketDirection,
    PcapngInterface,
    PcapngWriter,
)
from ._dialect import Dialect
from ._trace import TraceHook, TraceRecord

__all__ = ["CaptureFile", "LineCapture", "combine", "describe_line", "open_capture", "packet_marks"]

#: The longest a written packet stays in the file's buffer.
FLUSH_EVERY_S: Final = 0.5


def describe_line(protocol: str, line: LineSettings) -> str:
    """The interface description: ``"sj300 19200 8N1"``, ``"fr700 instant"`` (replay reads it)."""
    if not line.baudrate:
        return f"{protocol} instant"
    return f"{protocol} {line.baudrate} {line.bytesize}{line.parity}{line.stopbits}"


def packet_marks(frame: LineFrame) -> tuple[int, str]:
    """The error bits and comment a frame's packet carries (0 and ``""`` for a good one)."""
    if frame.role is FrameRole.NOISE:
        return FLAG_NOISE, f"noise: {frame.problem or 'bytes outside a frame'}"
    if frame.role is FrameRole.BROKEN:
        bits = FLAG_CHECK_ERROR if frame.check_ok is False else 0
        return bits, f"broken frame: {frame.problem}"
    return 0, ""


class CaptureFile:
    """A pcapng file being written (see the module docstring); close it when done.

    Raises:
        LocalProtocolError: the file cannot be created.
    """

    def __init__(self, path: str | Path | BinaryIO) -> None:
        # A binary stream (io.BytesIO: the workbench's "last N seconds" download) is
        # written and left open: its owner reads it, and closes it.
        self._owned = isinstance(path, str | Path)
        if isinstance(path, str | Path):
            self.path: Path | None = Path(path)
            try:
                self._file: BinaryIO = self.path.open("wb")
            except OSError as exc:
                raise LocalProtocolError(
                    f"cannot write capture {self.path}: {exc.strerror or exc}"
                ) from None
        else:
            self.path = None
            self._file = path
        self._closed = False
        self._writer = PcapngWriter()
        self._file.write(self._writer.section(f"sj300_async {__version__}"))
        self._flushed = time.monotonic()
        self._lines: list[LineCapture] = []
        #: Packets written so far, every line together.
        self.packets = 0
        #: Packets that came after the file was closed, so not in it.
        self.unwritten = 0

    @property
    def closed(self) -> bool:
        return self._closed or self._file.closed

    def line(self, dialect: Dialect[Any, Any], name: str, line: LineSettings) -> LineCapture:
        """A new interface for one line; the returned hook captures what that bus traces."""
        number, block = self._writer.interface(
            PcapngInterface(
                dialect.capture_linktype,
                name=name,
                description=describe_line(dialect.name, line),
                speed=line.baudrate,
            )
        )
        self._file.write(block)
        capture = LineCapture(self, number, dialect)
        self._lines.append(capture)
        return capture

    def write(self, packet: CapturedPacket) -> None:
        """Write one packet; after :meth:`close` it is counted in :attr:`unwritten`, not
        written (a bus may outlive its capture)."""
        if self.closed:
            self.unwritten += 1
            return
        self._file.write(self._writer.packet(packet))
        self.packets += 1
        now = time.monotonic()
        if now - self._flushed >= FLUSH_EVERY_S:
            self._file.flush()
            self._flushed = now

    def close(self) -> None:
        """Write what the lines still hold (an incomplete frame, as noise), and close.

        A stream given instead of a path is flushed, not closed.
        """
        if self.closed:
            return
        for line in self._lines:
            line.flush()
        self._closed = True
        if self._owned:
            self._file.close()
        else:
            self._file.flush()

    def __enter__(self) -> CaptureFile:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()


class LineCapture:
    """One line's interface: a :data:`TraceHook` that writes each frame as a packet."""

    def __init__(self, file: CaptureFile, interface: int, dialect: Dialect[Any, Any]) -> None:
        self._file = file
        self._interface = interface
        self._framer = dialect.line_framer()
        try:  # the loop's clock (the trace's timestamps) against the wall clock
            clock = asyncio.get_running_loop().time()
        except RuntimeError:
            clock = time.monotonic()
        self._epoch_offset = time.time() - clock
        self._last_rx = clock

    def __call__(self, record: TraceRecord) -> None:
        if record.direction == "tx":
            frame = self._framer.classify(record.data, outbound=True)
            self.write_frame(record.timestamp, frame, PacketDirection.OUTBOUND)
            return
        self._last_rx = record.timestamp
        for piece in self._framer.feed(record.data):
            frame = self._framer.classify(piece, outbound=False)
            self.write_frame(record.timestamp, frame, PacketDirection.INBOUND)

    def flush(self) -> None:
        """Capture an incomplete received frame as noise (the capture is closing)."""
        for piece in self._framer.flush():
            frame = self._framer.classify(piece, outbound=False)
            self.write_frame(self._last_rx, frame, PacketDirection.INBOUND)

    def write_frame(self, timestamp: float, frame: LineFrame, direction: PacketDirection) -> None:
        """Write one frame judged elsewhere (the sniffer's); *timestamp* is loop time."""
        bits, comment = packet_marks(frame)
        stamp = round((timestamp + self._epoch_offset) * 1_000_000)
        self._file.write(
            CapturedPacket(self._interface, stamp, frame.data, direction, bits, comment)
        )


def open_capture(capture: str | PathLike[str] | CaptureFile | None) -> CaptureFile | None:
    """The capture an ``open_bus``-like call was given: an open one as it is, a path opened.

    The caller closes what this opened (``result is not capture``).

    Raises:
        LocalProtocolError: the file cannot be created.
    """
    if capture is None or isinstance(capture, CaptureFile):
        return capture
    return CaptureFile(fspath(capture))


def combine(*hooks: TraceHook | None) -> TraceHook | None:
    """One hook that calls each given one in turn (None when none is given)."""
    present = [hook for hook in hooks if hook is not None]
    if not present:
        return None
    if len(present) == 1:
        return present[0]

    def both(record: TraceRecord) -> None:
        for hook in present:
            hook(record)

    return both
