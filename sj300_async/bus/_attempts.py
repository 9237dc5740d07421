"""The arbiter's records of its attempts: the one on the line, and the failed ones.

An attempt on the line is :class:`Outstanding` until it ends; a request that
got no valid answer is :class:`Pending` while its reply may still come (rule
9 of :mod:`._arbiter`); an attempt that failed on the sync request before it
raises :class:`SyncMissed`, so that the call's error can say so. Plain
records: what is done with them is in :mod:`._arbiter` and :mod:`._recovery`.
"""

from __future__ import annotations

import asyncio
from dataclasses import dataclass
from typing import Generic

from ..wire import BadFrame, ReplyTimeoutError
from ._dialect import ReplyT, RequestT
from ._stats import TransactionStats

__all__ = ["Outstanding", "Pending", "SyncMissed"]


@dataclass(slots=True)
class Outstanding(Generic[RequestT, ReplyT]):
    """The transaction currently on the line."""

    request: RequestT
    #: Resolves to the answer, or to None when the deadline passes.
    waiter: asyncio.Future[ReplyT | None]
    stats: TransactionStats
    #: The response time-out of this attempt, and the loop time it ends at.
    timeout: float
    deadline: float
    #: The loop time before which no genuine answer can arrive (rule 8).
    not_before: float
    bad_frame: BadFrame | None = None
    #: The scheduled re-output request (rule 7), at most one per attempt.
    reoutput: asyncio.TimerHandle | None = None


@dataclass(frozen=True, slots=True)
class Pending(Generic[RequestT]):
    """A request whose reply may still come (rule 9), until the loop time *expires*."""

    request: RequestT
    expires: float


class SyncMissed(ReplyTimeoutError):
    """An attempt that failed on its sync request (only ever seen inside the arbiter)."""
