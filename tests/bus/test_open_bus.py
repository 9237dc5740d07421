"""open_bus: its keyword arguments written once, its types kept honest, sim:// found by scheme.

- ``BusOptions`` is every keyword argument after ``protocol``, for the
  neutral :func:`sj300_async.bus.open_bus` and each overload of
  :func:`sj300_async.open_bus`; its docstring's Args name each one.
- :func:`sj300_async.open_bus` is typed by its ``protocol`` argument (none:
  SJ300), so a URL whose ``protocol=`` names another protocol, or a
  ``replay://`` capture of another, is refused before anything is opened;
  the neutral one, typed ``Bus[Any, Any]``, takes the protocol from the URL.
- The bus finds the ``sim://`` connector by the scheme in its registry, and
  imports the simulator only when such a bus is opened.
"""

from __future__ import annotations

import subprocess
import sys
import textwrap
from pathlib import Path
from typing import Any

import pytest

import sj300_async as sj
import sj300_async.bus as sjbus
from sj300_async.bus import BusOptions, SchemeConnector
from sj300_async.bus._registry import scheme_connector
from sj300_async.fr700 import Fr700Drive
from sj300_async.simulator._sim_connector import sim_connector
from sj300_async.simulator.fr700 import Fr700SimulatedBus

FIX = "so that the types follow the URL"

# -- the keyword arguments -------------------------------------------------------------------


def test_every_option_is_documented_once() -> None:
    doc = sjbus.open_bus.__doc__ or ""
    args = doc.partition("Args:")[2].partition("Raises:")[0]
    documented = {
        line.strip().partition(":")[0]
        for line in args.splitlines()
        if line.startswith(" " * 8) and not line.startswith(" " * 12) and ":" in line
    }
    assert documented == {"url", "protocol"} | set(BusOptions.__optional_keys__)
    assert not BusOptions.__required_keys__
    assert sj.open_bus.__doc__ == doc  # the user's open_bus shows the same Args


@pytest.mark.parametrize("open_bus", [sj.open_bus, sjbus.open_bus], ids=["root", "neutral"])
def test_an_unknown_keyword_is_refused_at_once(open_bus: Any) -> None:
    with pytest.raises(TypeError, match=r"unexpected keyword argument.* retrys"):
        open_bus("sim://", retrys=3)


async def test_the_options_reach_the_bus() -> None:
    options: BusOptions = {"retries": 0, "read_only": True, "timeout": 0.05}
    async with sj.open_bus("sim://?nodes=1", **options) as bus:
        assert bus.retries == 0
        assert bus.timing.fixed_timeout_s == 0.05
        with pytest.raises(sj.ReadOnlyError):
            await bus.drive(1).stop()
    async with sjbus.open_bus("sim://?nodes=1") as bus:  # none given: the defaults
        assert bus.retries == 2
        assert bus.timing.fixed_timeout_s is None


# -- the URL's protocol and the types --------------------------------------------------------


@pytest.mark.parametrize(
    ("url", "protocol", "named"),
    [
        ("sim://?protocol=fr700", None, "fr700"),
        ("sim://?nodes=1&protocol=FR700", None, "fr700"),  # read as the URL parser reads it
        ("sim://?protocol=fr700", "sj300", "fr700"),
        ("sim://?protocol=sj300", "fr700", "sj300"),
        ("tcp://127.0.0.1:1?protocol=fr700", None, "fr700"),
        ("serial:///dev/nonexistent?baudrate=9600&protocol=fr700", None, "fr700"),
    ],
)
def test_a_url_naming_another_protocol_than_the_types_is_refused(
    url: str, protocol: Any, named: str
) -> None:
    # Refused at the call, before the context is even entered: nothing is opened.
    with pytest.raises(sj.LocalProtocolError, match=f"pass protocol='{named}' {FIX}"):
        sj.open_bus(url, protocol=protocol)


async def test_a_url_that_agrees_with_the_types_opens() -> None:
    async with sj.open_bus("sim://?protocol=sj300&nodes=1") as bus:
        assert isinstance(bus.drive(1), sj.Drive)
    async with sj.open_bus("sim://?protocol=sj300&nodes=1", protocol="sj300") as bus:
        assert isinstance(bus.drive(1), sj.Drive)
    async with sj.open_bus("sim://?protocol=fr700&nodes=0", protocol="fr700") as fr700:
        assert isinstance(fr700.drive(0), Fr700Drive)
        assert isinstance(fr700.simulator, Fr700SimulatedBus)
        assert not (await fr700.drive(0).read_status()).running
    async with sj.open_bus("sim://?nodes=0", protocol="fr700") as fr700:  # the URL says nothing
        assert isinstance(fr700.drive(0), Fr700Drive)


async def test_the_neutral_open_bus_takes_the_protocol_from_the_url() -> None:
    async with sjbus.open_bus("sim://?protocol=fr700&nodes=0") as bus:
        assert bus.dialect.name == "fr700"
        assert isinstance(bus.drive(0), Fr700Drive)


async def test_a_replayed_capture_of_another_protocol_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "fr700.pcapng"
    async with sj.open_bus("sim://?nodes=0", protocol="fr700", capture=path) as live:
        expected = await live.drive(0).read_status()
    with pytest.raises(sj.LocalProtocolError, match="capture of fr700, not sj300: pass protoc"):
        async with sj.open_bus(f"replay://{path}"):
            pass
    async with sj.open_bus(f"replay://{path}", protocol="fr700") as bus:
        assert await bus.drive(0).read_status() == expected
    async with sjbus.open_bus(f"replay://{path}") as bus:  # the neutral one: as captured
        assert bus.dialect.name == "fr700"


# -- sim:// through the scheme registry ------------------------------------------------------


def test_sim_is_found_by_its_scheme() -> None:
    found: SchemeConnector | None = scheme_connector("sim")
    assert found is sim_connector
    typed: SchemeConnector = sim_connector  # mypy checks the signature against the protocol
    assert callable(typed)
    for real_line in ("tcp", "rfc2217", "serial", "replay"):
        assert scheme_connector(real_line) is None


async def test_faults_and_simulator_are_for_sim_only() -> None:
    with pytest.raises(sj.LocalProtocolError, match="sim:// buses only"):
        async with sj.open_bus("tcp://127.0.0.1:1", simulator=object()):
            pass


def test_the_simulator_is_imported_only_for_a_sim_bus() -> None:
    code = textwrap.dedent(
        """
        import asyncio, sys
        import sj300_async as sj

        def loaded():
            return any(m.startswith("sj300_async.simulator") for m in sys.modules)

        assert not loaded(), "importing the library loaded the simulator"

        async def main():
            try:
                async with sj.open_bus("tcp://127.0.0.1:1", retries=0):
                    pass
            except sj.TransportError:
                pass
            assert not loaded(), "a tcp:// bus loaded the simulator"
            async with sj.open_bus("sim://?nodes=1") as bus:
                await bus.drive(1).read_status()
            assert "sj300_async.simulator._sim_connector" in sys.modules

        asyncio.run(main())
        """
    )
    result = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=60, check=False
    )
    assert result.returncode == 0, result.stderr
