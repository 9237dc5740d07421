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
again. One full collection comes first, as Python's documentation advises:
frozen, the cycles made while the collector was paused would never be freed
(each key of asyncua's nodeset cache is read by ``ast.literal_eval``, whose
closures leave a cycle per call: 5.3 MiB kept, issue 44). The gateway's
stop moves the frozen back (:func:`thaw`), so that a process that starts
many gateways (the tests) collects what each left in cycles.

While a gateway runs, the youngest generation is collected after
:data:`YOUNG_OBJECTS` more objects than were freed, not Python's 700
(:func:`young_collections_raised`). A running gateway allocates and frees
at the same rate: each sample's snapshot, messages and values replace the
last, and live until the next sample. So the count of objects allocated
minus freed drifts by a few hundred at a time, and at 700 each young
collection found some ten thousand of them alive (each drive's latest
sample, not garbage), scanned them and moved them on to be scanned again
in the next generation: at 2,048 drives a second the collector took about
5 % of the gateway's CPU and freed almost nothing. Garbage that only the
collector frees (reference cycles) still starts a collection once
:data:`YOUNG_OBJECTS` of it exist.

Why 5,000 and not more: a young collection holds the event loop for as
long as it scans, about a microsecond per object on a loaded edge box.
At 20,000 (issue 30's choice, for CPU alone) each one held it 13-46 ms,
and a client sending requests as fast as the gateway answers them
(issue 41's attacks) made one every few hundred milliseconds: the loop's
p99 lag went to 53 ms against a budget of 50. At 5,000 they hold it 5-8
ms (3-14 ms under the combined attack).
"""

from __future__ import annotations

import contextlib
import gc
from collections.abc import Iterator
from typing import Final

__all__ = [
    "YOUNG_OBJECTS",
    "collector_paused",
    "freeze_long_lived",
    "thaw",
    "young_collections_raised",
]

#: Objects allocated beyond those freed before the youngest generation is collected,
#: while a gateway runs (Python's default: 700).
YOUNG_OBJECTS: Final = 5_000


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
    """Leave every object that exists now out of future collections, garbage collected
    first: what only the collector frees (cycles made while it was paused) would
    otherwise be kept for good."""
    gc.collect()
    gc.freeze()


def thaw() -> None:
    """Give the frozen objects back to the collector (the gateway stopped)."""
    gc.unfreeze()


#: The thresholds before the first running gateway raised them, and how many run.
_before: tuple[int, int, int] | None = None
_running = 0


@contextlib.contextmanager
def young_collections_raised() -> Iterator[None]:
    """The youngest generation's threshold at least :data:`YOUNG_OBJECTS` inside (module
    docstring); as it was once the last gateway of the process leaves."""
    global _before, _running
    if _running == 0:
        _before = gc.get_threshold()
        gc.set_threshold(max(_before[0], YOUNG_OBJECTS), *_before[1:])
    _running += 1
    try:
        yield
    finally:
        _running -= 1
        if _running == 0 and _before is not None:
            gc.set_threshold(*_before)
            _before = None
