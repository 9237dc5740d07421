"""The gateway's MQTT 3.1.1 client: a sans-IO codec (:mod:`._packets`) and its asyncio side.

See :mod:`._client` for why the gateway has its own client and how it
publishes.
"""

from __future__ import annotations

from ._client import Client
from ._packets import MalformedPacket, PacketParser
from ._types import Message, MqttError, PublishUnacknowledged, SubscribeUnacknowledged, Will

__all__ = [
    "Client",
    "MalformedPacket",
    "Message",
    "MqttError",
    "PacketParser",
    "PublishUnacknowledged",
    "SubscribeUnacknowledged",
    "Will",
]
