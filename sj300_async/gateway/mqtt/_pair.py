"""The MQTT northbound when it is more than one client: the JSON bridge and the Sparkplug node.

Each keeps its own connection (an MQTT connection has one last will: the
bridge's says ``offline`` on its availability topic, Sparkplug's is the edge
node's NDEATH); to the gateway they are one northbound, ``[mqtt]``. They
start in order and a failed start closes what started; every call goes to
each, and a ``publish`` that raises in one still reaches the other. A
sample's state message is built once, by the first client, for them all
(:class:`StatePublisher`): both read the same fields of the same drive as
served.
"""

from __future__ import annotations

import logging
from collections.abc import Iterator, Sequence
from typing import TYPE_CHECKING, Protocol

from .. import GatewayView, Northbound, ServedDrive
from ._topics import StateMessage

if TYPE_CHECKING:
    from prometheus_client.core import Metric

__all__ = ["Clients", "StatePublisher"]

_log = logging.getLogger("sj300_async.gateway.mqtt")


class StatePublisher(Northbound, Protocol):
    """An MQTT client that publishes a sample from its state message."""

    def state_of(self, served: ServedDrive) -> StateMessage: ...

    def publish_state(self, served: ServedDrive, message: StateMessage) -> None: ...

    def problems(self) -> list[str]: ...

    def flush(self) -> None: ...


class Clients:
    """Several MQTT clients as one northbound (see the module docstring)."""

    def __init__(self, parts: Sequence[StatePublisher]) -> None:
        self.parts = tuple(parts)

    async def start(self, gateway: GatewayView) -> None:
        started: list[StatePublisher] = []
        try:
            for part in self.parts:
                await part.start(gateway)
                started.append(part)
        except BaseException:
            for part in reversed(started):
                await part.close()
            raise

    def announce(self) -> str | None:
        lines = [line for part in self.parts if (line := part.announce()) is not None]
        return "\n".join(lines) if lines else None

    def publish(self, served: ServedDrive) -> None:
        failure: Exception | None = None
        message = self.parts[0].state_of(served)
        for part in self.parts:
            try:
                part.publish_state(served, message)
            except Exception as exc:  # the gateway counts it; the other part still gets it
                failure = failure or exc
        if failure is not None:
            raise failure

    def flush(self) -> None:
        for part in self.parts:
            part.flush()

    def metrics(self) -> Iterator[Metric]:
        for part in self.parts:
            yield from part.metrics()

    def problems(self) -> list[str]:
        return [problem for part in self.parts for problem in part.problems()]

    async def close(self) -> None:
        for part in reversed(self.parts):
            await part.close()
