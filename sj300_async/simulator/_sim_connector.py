"""The ``sim://`` line: simulated drives behind an in-memory transport, for the bus.

The bus does not know the simulator: it finds :func:`sim_connector` by the
URL's scheme in its registry (:mod:`sj300_async.bus._registry`) and imports
this module only when a ``sim://`` bus is opened, so this is a plug-in of
the bus, as a python-can interface is of ``can.Bus``. The simulated line is
the protocol's own (``Dialect.simulator``, a
:class:`~sj300_async.bus.SimulatorFactory`), served by a
:class:`~sj300_async.simulator.SimulatorEndpoint` through the loopback
transport, with the URL's options:

- ``nodes=``: the simulated nodes (parsed with the URL);
- ``wait_ms=``: every drive's wait time (the drives' own default otherwise);
- ``factory_defaults=1``: the drives start from factory settings;
- ``pace=1``: every character takes its wire time at the line's speed.
"""

from __future__ import annotations

from typing import Any

from ..bus import (
    BusAddress,
    Dialect,
    SchemeConnection,
    SimulatorFactory,
    load_object,
    parse_flag,
)
from ..transports import LineFaults, loopback_connector
from ..wire import LineSettings, LocalProtocolError
from ._endpoint import SimulatorEndpoint
from ._pacing import LinePacing, PacedLine, PlausibleLine

__all__ = ["sim_connector"]


def _wait_ms(options: dict[str, str]) -> int | None:
    """The URL's ``wait_ms=``, or None when it is not given."""
    text = options.get("wait_ms")
    if text is None:
        return None
    try:
        return int(text)
    except ValueError:
        raise LocalProtocolError(f"wait_ms must be an integer, got {text!r}") from None


def sim_connector(
    address: BusAddress,
    *,
    line: LineSettings,
    dialect: Dialect[Any, Any],
    faults: tuple[LineFaults | None, LineFaults | None] | None,
    simulator: Any,
) -> SchemeConnection:
    """The connection of a ``sim://`` bus (a :class:`~sj300_async.bus.SchemeConnector`).

    Args:
        address: the parsed ``sim://`` URL: its nodes and options.
        line: the bus's line settings; with a speed, no reply arrives sooner
            than that line could carry it (``pace=1``: every character takes
            its wire time); speed 0 is an instant line.
        dialect: the protocol; its ``simulator`` builds the simulated line.
        faults: (to-drive, to-host) line faults of the loopback transport, or None.
        simulator: serve this simulated line instead of a new one (its nodes
            replace the URL's; ``wait_ms=`` still applies to its drives), or None.

    Returns:
        The loopback connector (one endpoint per connection) and the simulated
        line it serves, which the bus shows as ``bus.simulator``.

    Raises:
        LocalProtocolError: a bad ``wait_ms=``, ``factory_defaults=`` or
            ``pace=``, or a *simulator* that speaks another protocol.
    """
    options = address.sim_options
    wait_ms = _wait_ms(options)
    if simulator is None:
        factory: SimulatorFactory = load_object(dialect.simulator)
        simulator = factory(
            dialect,
            address.nodes,
            factory_defaults=parse_flag("factory_defaults", options.get("factory_defaults", "0")),
            wait_ms=wait_ms,
        )
    elif getattr(simulator, "protocol", None) != dialect.name:
        raise LocalProtocolError(f"simulator {simulator!r} does not speak {dialect.name}")
    elif wait_ms is not None:
        for drive in simulator.drives.values():
            drive.set_wait_ms(wait_ms)
    # pace=1: every character takes its wire time. Unpaced on a line with a
    # speed: the drives answer at once but no reply arrives sooner than the
    # request and a short reply could cross that line (PlausibleLine), or the
    # host's plausibility floor would refuse every answer. Instant line: at once.
    pacing = LinePacing(line.baudrate, line.bytesize, line.parity, line.stopbits)
    paced = parse_flag("pace", options.get("pace", "0"))

    def wire() -> PacedLine | None:  # one per connection: a line is booked per endpoint
        if paced:
            return PacedLine(pacing)
        return PlausibleLine(pacing) if pacing.baudrate else None

    to_peer, to_host = faults or (None, None)
    served = simulator
    connector = loopback_connector(
        lambda send: SimulatorEndpoint(served, send=send, line=wire()),
        to_peer=to_peer,
        to_host=to_host,
    )
    return SchemeConnection(connector, simulator)
