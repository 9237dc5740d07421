"""The gateway's long-lived objects, kept out of the cyclic garbage collector's way.

A gateway builds most of what it will ever hold at start: the lines, the
drives, and above all the northbounds' models (an OPC UA address space is
about 9,600 Python objects per drive: asyncua keeps some 24 attribute
values per node). CPython's collector scans every tracked object at each
full collection, and starts one whenever the objects that survived enough
collections grew by a quarter: while such a model is built, it runs again
and again over an ever larger heap (more than half of the start-up), and
later each full collection over millions of objects holds the event loop
(and every line's poll) for as long as the scan takes.

So the collector is paused while the northbounds start
(:func:`collector_paused`), and what exists once the gateway runs is moved
to the collector's permanent generation (:func:`freeze_long_lived`, Python's
``gc.freeze``): still freed by reference counting as usual, never scanned
again. The gateway's stop moves it back (:func:`thaw`), so that a process
that starts many gateways (the tests) collects what each left in cycles.
"""

from __future__ import annotations

import contextlib
import gc
from collections.abc import Iterator

__all__ = ["collector_paused", "freeze_long_lived", "thaw"]


@contextlib.contextmanager
def collector_paused() -> Iterator[None]:
    """No automatic collection inside (as it was after: a collector off stays off)."""
    was = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if was:
            gc.enable()


def freeze_long_lived() -> None:
    """Leave every object that exists now out of future collections."""
    gc.freeze()


def thaw() -> None:
    """Give the frozen objects back to the collector (the gateway stopped)."""
    gc.unfreeze()
