"""A line's health, as every door serves it (gateway/_line_health.py)."""

from __future__ import annotations

import pytest

from sj300_async.gateway._line_health import UTILISATION_WINDOW_S, UtilisationMeter


def test_the_utilisation_is_none_until_a_window_has_passed() -> None:
    meter = UtilisationMeter()
    assert meter.read(10.0, 0.0) is None
    assert meter.read(10.0 + UTILISATION_WINDOW_S / 2, 0.3) is None  # too short a window


def test_the_utilisation_is_the_busy_share_of_the_window_whoever_asks() -> None:
    meter = UtilisationMeter()
    meter.read(10.0, 2.0)
    assert meter.read(11.0, 2.25) == pytest.approx(0.25)
    # A second door asking within the window gets the same figure, the mark unmoved.
    assert meter.read(11.5, 2.9) == pytest.approx(0.25)
    # The next window counts from the first door's mark (11.0, 2.25).
    assert meter.read(12.0, 2.75) == pytest.approx(0.5)


def test_the_utilisation_stays_within_0_and_1() -> None:
    meter = UtilisationMeter()
    meter.read(0.0, 0.0)
    assert meter.read(1.0, 1.5) == 1.0  # echo bytes counted twice, a clock step: never above
    assert meter.read(2.0, 1.0) == 0.0  # a bus reopened with its counters anew: never below
