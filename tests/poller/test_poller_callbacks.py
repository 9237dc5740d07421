"""An on_sample callback that raises (issue 14, item 5)."""

from __future__ import annotations

import logging

import pytest
from waiting import wait_for

import sj300_async as sj


class _Boom(Exception):
    pass


def _boom(sample: sj.Sample) -> None:
    raise _Boom(f"node {sample.node}")


async def test_callback_errors_are_logged_counted_and_polling_goes_on(
    caplog: pytest.LogCaptureFixture,
) -> None:
    async with sj.open_bus("sim://?nodes=1-2", timeout=0.02, retries=0) as bus:
        poller = sj.Poller(interval_s=0.005)
        poller.add(bus, [1, 2])
        poller.on_sample(_boom)
        seen: list[sj.Sample] = []
        poller.on_sample(seen.append)  # a later callback still runs
        with caplog.at_level(logging.ERROR, logger="sj300_async.poller"):
            async with poller:
                await wait_for(lambda: len(seen) >= 6, "six samples")
                await wait_for(lambda: poller.bus_stats(bus).cycles >= 3, "three cycles")
        stats = poller.bus_stats(bus)
        assert stats.callback_errors >= 6
        records = [r for r in caplog.records if r.name == "sj300_async.poller"]
        assert records
        assert all(r.levelno == logging.ERROR for r in records)
        assert records[0].exc_info is not None
        assert records[0].exc_info[0] is _Boom
        assert "on_sample callback" in records[0].getMessage()


async def test_callback_errors_raise_stops_the_poller() -> None:
    async with sj.open_bus("sim://?nodes=1", timeout=0.02, retries=0) as bus:
        poller = sj.Poller(interval_s=0.005, callback_errors="raise")
        poller.add(bus, [1])
        poller.on_sample(_boom)
        with pytest.RaisesGroup(_Boom, flatten_subgroups=True):
            async with poller:
                await wait_for(lambda: False, "the poller's failure", timeout=2.0)
        assert poller.bus_stats(bus).callback_errors == 0


def test_callback_errors_must_be_log_or_raise() -> None:
    with pytest.raises(sj.LocalProtocolError, match="callback_errors"):
        sj.Poller(callback_errors="ignore")  # type: ignore[arg-type]
