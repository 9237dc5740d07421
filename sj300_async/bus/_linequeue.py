"""Who may use the line next: a lock with two priorities, first come first served within each.

asyncio.Lock is not enough: it has no priorities (a stop must not wait behind
a queue of polls), and the waiters it wakes can lose the lock to a task that
arrives in between. Here ``release`` hands the line directly to the next
waiter, so order is exactly arrival order within a priority, urgent first.
"""

from __future__ import annotations

import asyncio
from collections import deque

__all__ = ["LineQueue"]


class LineQueue:
    """A fair two-priority lock for one half-duplex line."""

    def __init__(self) -> None:
        self._busy = False
        self._urgent: deque[asyncio.Future[None]] = deque()
        self._normal: deque[asyncio.Future[None]] = deque()

    @property
    def waiting(self) -> int:
        """Number of tasks waiting for the line."""
        return len(self._urgent) + len(self._normal)

    @property
    def busy(self) -> bool:
        """True while a task holds the line."""
        return self._busy

    def take(self) -> bool:
        """Take the line at once if it is free and nobody waits; False otherwise.

        The arbiter's fast path: a coroutine call costs more than the whole
        test, and on a line without contention the line is nearly always free.
        """
        if self._busy or self._urgent or self._normal:
            return False
        self._busy = True
        return True

    async def acquire(self, urgent: bool = False) -> None:
        """Wait for the line. Urgent requests go before every normal one.

        Cancelling a waiting task removes it from the queue; if the line had
        just been handed to it, the line is passed on to the next waiter.
        """
        if not self._busy and not self._urgent and not self._normal:
            self._busy = True
            return
        waiter: asyncio.Future[None] = asyncio.get_running_loop().create_future()
        queue = self._urgent if urgent else self._normal
        queue.append(waiter)
        try:
            await waiter
        except asyncio.CancelledError:
            if waiter.done() and not waiter.cancelled():
                self.release()  # we were handed the line as we were cancelled: pass it on
            elif waiter in queue:  # release() may already have skipped it
                queue.remove(waiter)
            raise

    def release(self) -> None:
        """Hand the line to the next waiter, or mark it free."""
        if not self._urgent and not self._normal:
            self._busy = False  # nobody waits: the commonest case, without the loops
            return
        for queue in (self._urgent, self._normal):
            while queue:
                waiter = queue.popleft()
                if not waiter.done():
                    waiter.set_result(None)
                    return
        self._busy = False
