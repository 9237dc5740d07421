"""Keep the cyclic garbage collector's pauses out of a run that judges frames by their timing.

The bus's plausibility floor judges a frame by when the host *read* it. A
host paused for longer than the margin between a duplicated reply and the
floor (a generation-2 collection in a pytest process of 3,000 tests takes
tens of milliseconds) reads the copy as late as the answer itself, and no
host can tell them apart: docs/RELIABILITY.md lists it among what stays
undetectable. The duplicate runs test the bus under the adversary's line,
not that limit, so they run with the collector frozen and off (objects made
during the run are collected once it ends).
"""

from __future__ import annotations

import contextlib
import gc
from collections.abc import Iterator

__all__ = ["no_collector_pauses"]


@contextlib.contextmanager
def no_collector_pauses() -> Iterator[None]:
    """Collect now, then keep the cyclic collector off until the block ends."""
    was_enabled = gc.isenabled()
    gc.collect()
    gc.freeze()  # what exists now is never scanned again during the block
    gc.disable()
    try:
        yield
    finally:
        gc.unfreeze()
        if was_enabled:
            gc.enable()
