"""Line faults for the loopback transport: what a noisy RS-485 line does to bytes.

Each chunk passing through :meth:`LineFaults.apply` may have bytes corrupted
(one bit flipped), dropped, inserted (random noise bytes), duplicated, be
split into fragments, and be delayed. Order is preserved: a delayed chunk
holds back everything after it, as on a real wire. Randomness comes from
the given ``random.Random`` so a failing run can be replayed from its seed.
Every fault is counted by kind in :attr:`LineFaults.counts`.
"""

from __future__ import annotations

import random
from collections import Counter
from dataclasses import dataclass, field

__all__ = ["LineFaults"]


@dataclass
class LineFaults:
    """Fault rates for one direction of a loopback line (all rates per byte or per chunk)."""

    rng: random.Random = field(default_factory=random.Random)
    #: Per byte: flip one random bit.
    corrupt_rate: float = 0.0
    #: Per byte: drop it.
    drop_rate: float = 0.0
    #: Per byte: insert a random byte before it.
    insert_rate: float = 0.0
    #: Per byte: send it twice.
    duplicate_rate: float = 0.0
    #: Split chunks into fragments of 1..fragment_max bytes (0: keep chunks whole).
    fragment_max: int = 0
    #: Per chunk: delay it by up to this many seconds.
    delay_max_s: float = 0.0
    #: Per chunk: probability that the delay is applied.
    delay_rate: float = 0.0
    #: How many faults of each kind were injected.
    counts: Counter[str] = field(default_factory=Counter)

    def mangle(self, data: bytes) -> bytes:
        """Apply the per-byte faults to *data*."""
        if not (self.corrupt_rate or self.drop_rate or self.insert_rate or self.duplicate_rate):
            return data
        rng = self.rng
        out = bytearray()
        for byte in data:
            if self.insert_rate and rng.random() < self.insert_rate:
                out.append(rng.randrange(256))
                self.counts["inserted"] += 1
            if self.drop_rate and rng.random() < self.drop_rate:
                self.counts["dropped"] += 1
                continue
            if self.corrupt_rate and rng.random() < self.corrupt_rate:
                byte ^= 1 << rng.randrange(8)
                self.counts["corrupted"] += 1
            out.append(byte)
            if self.duplicate_rate and rng.random() < self.duplicate_rate:
                out.append(byte)
                self.counts["duplicated"] += 1
        return bytes(out)

    def apply(self, data: bytes) -> list[tuple[float, bytes]]:
        """Return the fragments of *data* to deliver, each with its delay in seconds."""
        data = self.mangle(data)
        if self.fragment_max > 0 and len(data) > 1:
            pieces = []
            pos = 0
            while pos < len(data):
                size = self.rng.randint(1, self.fragment_max)
                pieces.append(data[pos : pos + size])
                pos += size
            if len(pieces) > 1:
                self.counts["fragmented"] += 1
        else:
            pieces = [data]
        delay = 0.0
        if self.delay_rate and self.rng.random() < self.delay_rate:
            delay = self.rng.uniform(0, self.delay_max_s)
            self.counts["delayed"] += 1
        return [(delay, piece) for piece in pieces if piece]
