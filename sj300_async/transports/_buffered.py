"""Socket reads into one reused buffer, for every protocol of the library.

asyncio hands a plain :class:`asyncio.Protocol` each read as a new ``bytes``
from ``sock.recv(256 KiB)``: CPython allocates the 256 KiB, the kernel
copies the 14 bytes of a status reply into it, and the object is shrunk and
later freed. On glibc an allocation that size is an ``mmap`` unless an
earlier free happened to raise the allocator's threshold, so whether every
read also costs ``mmap`` + ``mremap`` + ``munmap`` and a page fault depends
on what the process did before; a freshly started process pays them on
every read. The tcp benchmark's two floors, a bare client on each read path
(``benchmarks/_floor.py``), measure the difference.

An :class:`asyncio.BufferedProtocol` lets the transport ``recv_into`` a
buffer of ours instead, and this one keeps a single one for its life: the
chunk is copied out as ``bytes`` (a small allocation from Python's own
allocator, no system call) and handed to :meth:`data_received` as usual. The
class stays an :class:`asyncio.Protocol` as well: a transport that knows
nothing of buffered protocols (pyserial-asyncio-fast, the RFC 2217 and
loopback transports) calls :meth:`data_received` directly.
"""

from __future__ import annotations

import asyncio
from typing import Final

__all__ = ["READ_BUFFER_BYTES", "BufferedReads"]

#: The most one read takes from the socket. An RS-485 line delivers at most
#: 11.5 kB/s at 115200 baud and a reply is at most a few hundred bytes, so a
#: read rarely fills even a fraction of it; a longer burst is read over more
#: loop iterations, nothing is lost.
READ_BUFFER_BYTES: Final = 16384


class BufferedReads(asyncio.BufferedProtocol, asyncio.Protocol):
    """A protocol whose transport reads into one buffer it keeps; subclasses
    implement :meth:`data_received` only, as for a plain protocol."""

    def __init__(self) -> None:
        self._read_view = memoryview(bytearray(READ_BUFFER_BYTES))

    def get_buffer(self, sizehint: int) -> memoryview:
        # sizehint is -1 from asyncio's socket transports: any size will do.
        return self._read_view

    def buffer_updated(self, nbytes: int) -> None:
        self.data_received(self._read_view[:nbytes].tobytes())
