"""The gateway's MQTT 3.1.1 client: a sans-IO codec (:mod:`._packets`) and its asyncio side.

See :mod:`._client` for why the gateway has its own client and how it
publishes.
"""

from __future__ import annotations

from ._client import Client, Message, MqttError, PublishUnacknowledged, Will
from ._packets import MalformedPacket, PacketParser

__all__ = [
    "Client",
    "MalformedPacket",
    "Message",
    "MqttError",
    "PacketParser",
    "PublishUnacknowledged",
    "Will",
]
