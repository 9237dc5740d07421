"""The gateway keeps its long-lived objects out of the garbage collector's scans (gateway/_heap.py).

What it guards against (a full collection over an OPC UA address space of
millions of objects, at start and later in the middle of polls) is
measured in the plant benchmark and the CHANGELOG; here, the mechanism:
the collector runs again once the gateway runs, what the gateway built is
frozen while it runs, and given back when it stops. Only when asked
(``tune_collector``, which the ``sj300 gateway`` command sets): an
application that embeds a Gateway keeps its collector as it set it.
"""

from __future__ import annotations

import gc
import weakref

import pytest

from sj300_async.gateway import GatewayStartError
from sj300_async.gateway._heap import YOUNG_OBJECTS, collector_paused, freeze_long_lived, thaw

from .conftest import running_gateway

CONFIG = """
[gateway]
id = "heap"
[[lines]]
name = "hall"
url = "sim://?nodes=1-2"
nodes = "1-2"
"""


async def test_what_the_gateway_built_is_frozen_while_it_runs() -> None:
    gc.unfreeze()
    before = gc.get_threshold()
    async with running_gateway(CONFIG, tune_collector=True) as gateway:
        assert gc.isenabled()  # paused only while the northbounds started
        assert gc.get_threshold() == (YOUNG_OBJECTS, *before[1:])
        assert gc.get_freeze_count() > 0
        drive = gateway.drives[0]
        assert not any(o is drive for o in gc.get_objects())  # out of every scan
    assert gc.get_freeze_count() == 0
    assert any(o is drive for o in gc.get_objects())  # collectable again
    assert gc.get_threshold() == before


async def test_young_collections_stay_raised_until_the_last_gateway_stops() -> None:
    before = gc.get_threshold()
    raised = (YOUNG_OBJECTS, *before[1:])
    async with running_gateway(CONFIG, tune_collector=True):
        second = CONFIG.replace('id = "heap"', 'id = "heap2"')
        async with running_gateway(second, tune_collector=True):
            assert gc.get_threshold() == raised
        assert gc.get_threshold() == raised  # the first one still runs
    assert gc.get_threshold() == before


async def test_a_failed_start_leaves_the_collector_as_it_was() -> None:
    gc.unfreeze()
    text = CONFIG + '[modbus]\nlisten = "203.0.113.7:5020"\n'  # not an address of this host
    with pytest.raises(GatewayStartError):
        async with running_gateway(text, tune_collector=True):
            pass
    assert gc.isenabled()
    assert gc.get_freeze_count() == 0
    assert gc.get_threshold()[0] != YOUNG_OBJECTS


async def test_an_embedded_gateway_leaves_the_collector_alone_unless_asked() -> None:
    gc.unfreeze()
    before = gc.get_threshold()
    async with running_gateway(CONFIG) as gateway:
        assert gc.get_threshold() == before
        assert gc.get_freeze_count() == 0
        drive = gateway.drives[0]
        assert any(o is drive for o in gc.get_objects())  # scanned as any other object
    assert gc.get_threshold() == before


class _Cycle:
    """An object that refers to itself: freed only by the collector."""

    def __init__(self) -> None:
        self.me = self


def test_cycles_made_while_the_collector_was_paused_are_not_frozen() -> None:
    """What the northbounds' start leaves in cycles (asyncua's nodeset cache leaves one
    per key read) is garbage, not a long-lived object: collected before the freeze."""
    gc.unfreeze()
    with collector_paused():
        gone = weakref.ref(_Cycle())
        assert gone() is not None  # the collector is paused: the cycle is still there
        freeze_long_lived()
    try:
        assert gone() is None
        assert gc.get_freeze_count() > 0
    finally:
        thaw()
