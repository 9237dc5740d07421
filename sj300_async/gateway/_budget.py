"""Budgets a door spends before costly work: per client address, per user name, in all.

Every door that does something costly for a client that has not proved
who it is (a password check, a session slot, a body read) spends from a
:class:`KeyedBudget` first, keyed by what the attacker cannot choose
freely (the client's address) and, where a name is sent, by that name too.
A burst past the budget is refused at once, unchecked, and counted; the
refusal costs a dictionary lookup, not the work.

Decisions:

- **Token buckets, not windows.** Each key holds up to ``burst`` tokens and
  regains ``per_s`` a second: a legitimate client that mistypes once is
  never refused, and a stream settles to the refill rate.
- **Bounded memory.** At most ``max_keys`` keys are kept; a newcomer past
  that evicts the key idle longest (a full bucket, usually). A scan from
  many addresses costs the table's size, not the process's memory, and an
  evicted key starts full again, which only helps a legitimate client.
- **Sans-IO but for the clock**, so the tests drive time.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Final

__all__ = ["DEFAULT_MAX_KEYS", "KeyedBudget"]

#: Keys a budget keeps at most (the idlest goes first).
DEFAULT_MAX_KEYS: Final = 4096


class KeyedBudget:
    """A token bucket per key (see the module docstring).

    Args:
        burst: tokens a key holds at most (what a burst may spend at once).
        per_s: tokens a key regains a second.
        max_keys: keys kept at most.
        clock: seconds, monotonic.
    """

    __slots__ = ("_buckets", "_clock", "burst", "max_keys", "per_s", "refused")

    def __init__(
        self,
        burst: float,
        per_s: float,
        *,
        max_keys: int = DEFAULT_MAX_KEYS,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        if burst < 1 or per_s <= 0 or max_keys < 1:
            raise ValueError("a budget needs burst >= 1, per_s > 0 and max_keys >= 1")
        self.burst = float(burst)
        self.per_s = float(per_s)
        self.max_keys = max_keys
        self._clock = clock
        #: key -> (tokens, when they were counted); insertion order is idleness order.
        self._buckets: dict[object, tuple[float, float]] = {}
        #: Spends refused since the start.
        self.refused = 0

    def __len__(self) -> int:
        return len(self._buckets)

    def _tokens(self, key: object, now: float) -> float:
        held = self._buckets.pop(key, None)  # popped: re-inserted last (the most recent)
        if held is None:
            return self.burst
        tokens, at = held
        return min(self.burst, tokens + (now - at) * self.per_s)

    def available(self, key: object) -> float:
        """Tokens *key* holds now (nothing is spent)."""
        held = self._buckets.get(key)
        if held is None:
            return self.burst
        tokens, at = held
        return min(self.burst, tokens + (self._clock() - at) * self.per_s)

    def spend(self, key: object, cost: float = 1.0) -> bool:
        """Spend *cost* of *key*'s tokens: True, or False (counted, nothing spent) when short."""
        now = self._clock()
        tokens = self._tokens(key, now)
        allowed = tokens >= cost
        if allowed:
            tokens -= cost
        else:
            self.refused += 1
        if tokens < self.burst:  # a full bucket is the default: not kept
            self._buckets[key] = (tokens, now)
            while len(self._buckets) > self.max_keys:
                del self._buckets[next(iter(self._buckets))]
        return allowed

    def refund(self, key: object, cost: float = 1.0) -> None:
        """Give back *cost* (a check that succeeded need not count against its client)."""
        now = self._clock()
        tokens = min(self.burst, self._tokens(key, now) + cost)
        if tokens < self.burst:
            self._buckets[key] = (tokens, now)

    def retry_after_s(self, key: object, cost: float = 1.0) -> float:
        """Seconds until *key* can spend *cost* (0 when it can now): a 429's Retry-After."""
        missing = cost - self.available(key)
        return 0.0 if missing <= 0 else missing / self.per_s
