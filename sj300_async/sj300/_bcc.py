"""Block check code: XOR of every byte between STX and the BCC itself."""

from __future__ import annotations

__all__ = ["bcc", "xor_bytes"]

# Upper-case two-character hex for every byte value, built once.
_HEX_TABLE: tuple[bytes, ...] = tuple(b"%02X" % i for i in range(256))


def _fold_shifts(n: int) -> tuple[int, ...]:
    width = 1
    while width < n:
        width *= 2
    shifts = []
    while width > 1:
        width //= 2
        shifts.append(8 * width)
    return tuple(shifts)


# Shift sequence per body length: halve the next power of two down to one byte.
_SHIFTS: tuple[tuple[int, ...], ...] = tuple(_fold_shifts(n) for n in range(1025))
_from_bytes = int.from_bytes  # bound once: looking it up on int costs as much as a fold


def xor_bytes(body: bytes | bytearray | memoryview) -> int:
    """Return the XOR of all bytes of *body*.

    Instead of a Python loop per byte, the bytes are read as one big integer
    and folded onto themselves: with the width rounded up to a power of two,
    ``v ^= v >> (8 * half)`` puts the XOR of the two halves into the lower
    half, and log2(n) such steps (done in C) leave the answer in the lowest
    byte. Rounding up to a power of two means the bytes above the current
    half never need masking. A 446-byte trip-history reply takes 9 folds.
    """
    value = _from_bytes(body)  # big-endian: the byte order does not matter to a XOR
    n = len(body)
    # The lengths a line carries most, folded without the loop: up to 16 bytes
    # (every request, ACK, NAK, status and parameter reply) and up to 128 (the
    # monitor block). A fold wider than needed only XORs in zeros. Unrolled,
    # a short body runs fewer bytecodes than the loop (benchmarks.profile_tcp
    # counts them).
    if n <= 16:
        value ^= value >> 64
        value ^= value >> 32
        value ^= value >> 16
        value ^= value >> 8
        return value & 0xFF
    if n <= 128:
        value ^= value >> 512
        value ^= value >> 256
        value ^= value >> 128
        value ^= value >> 64
        value ^= value >> 32
        value ^= value >> 16
        value ^= value >> 8
        return value & 0xFF
    for shift in _SHIFTS[n] if n < len(_SHIFTS) else _fold_shifts(n):
        value ^= value >> shift
    return value & 0xFF


def bcc(body: bytes) -> bytes:
    """Return the block check code of *body* as two upper-case hex ASCII characters.

    *body* is everything between STX and the BCC: node, command and data in a
    request; node, ACK/NAK, error code and data in a reply.

    >>> bcc(b"01001")
    b'30'
    """
    return _HEX_TABLE[xor_bytes(body)]
