"""The client's values: what it raises, what it delivers, and its will. Sans-IO.

Every failure is an :class:`MqttError`; a connection ended by the broker's
silence about one of our requests is a subclass, so that a session counts it
apart from other losses (``sj300_mqtt_puback_timeouts_total``,
``sj300_mqtt_suback_timeouts_total``) and :mod:`._acks` can word it
without the asyncio side.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["Message", "MqttError", "PublishUnacknowledged", "SubscribeUnacknowledged", "Will"]


class MqttError(Exception):
    """The connection could not be made, was refused, or was lost."""


class PublishUnacknowledged(MqttError):
    """A QoS 1 publish waited ``keepalive_s`` for its PUBACK: the connection was ended."""


class SubscribeUnacknowledged(MqttError):
    """A SUBSCRIBE (or UNSUBSCRIBE) waited ``keepalive_s`` for its answer: the connection ended."""


@dataclass(frozen=True, slots=True)
class Will:
    """The message the broker publishes for us if the connection ends without DISCONNECT."""

    topic: str
    payload: bytes | str
    qos: int = 0
    retain: bool = False


@dataclass(frozen=True, slots=True)
class Message:
    """A message the broker delivered."""

    topic: str
    #: Only the first bytes when ``length`` is past the client's ``max_publish_bytes``.
    payload: bytes
    qos: int
    retain: bool
    #: The payload's length as the broker sent it.
    length: int

    @property
    def skipped(self) -> bool:
        """The payload was too long to read (``payload`` is only its first bytes)."""
        return self.length != len(self.payload)
