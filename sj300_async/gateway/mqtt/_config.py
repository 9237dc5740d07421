"""``[mqtt]``: the broker the gateway publishes to, and how.

The URL is ``mqtt://HOST[:PORT]`` or ``mqtts://`` (ports 1883 and 8883 by
default); credentials have their own keys (a URL ends up in logs). A
``tls_ca`` must exist now: a missing file found at connect time would be a
retry loop, not an error. A relative ``tls_ca`` is relative to the
configuration file. The client id defaults to ``sj300-<gateway id>``.

Sparkplug B (``sparkplug = true``, docs/GATEWAY.md "Sparkplug B") needs a
``group_id`` and takes an optional ``primary_host_id``; its edge node id is
the gateway's id. It connects apart, as ``<client id>-spb`` (an MQTT
connection has one last will, and Sparkplug's is the edge node's NDEATH).
``state_topics = false`` leaves the JSON topics and discovery out, for a
plant that reads only Sparkplug.
"""

from __future__ import annotations

import urllib.parse
from dataclasses import dataclass, field
from pathlib import Path
from typing import Final

from .. import ConfigTable, SectionContext, valid_name
from ._topics import DEFAULT_PREFIX, DISCOVERY_PREFIX

__all__ = ["MQTT_KEYS", "MqttConfig", "SparkplugConfig", "parse_mqtt_section"]

MQTT_KEYS: Final = (
    *("url", "client_id", "username", "password", "tls_ca", "prefix", "qos"),
    *("discovery", "discovery_prefix", "keepalive_s"),
    *("state_topics", "sparkplug", "group_id", "primary_host_id"),
)
_PORTS: Final = {"mqtt": 1883, "mqtts": 8883}


@dataclass(frozen=True, slots=True)
class SparkplugConfig:
    """Sparkplug B on the same broker (docs/GATEWAY.md, "Sparkplug B")."""

    #: The Sparkplug group the gateway's edge node belongs to.
    group_id: str
    #: The primary host application the edge node waits for (its STATE), or None.
    primary_host_id: str | None = None


@dataclass(frozen=True, slots=True)
class MqttConfig:
    """The MQTT broker the gateway publishes to (docs/GATEWAY.md, "MQTT")."""

    host: str
    port: int
    #: TLS: an ``mqtts://`` URL, or a ``tls_ca`` given.
    tls: bool = False
    #: The MQTT client id (the configuration's default: ``sj300-<gateway id>``).
    client_id: str = "sj300"
    username: str | None = None
    password: str | None = field(default=None, repr=False)
    #: The CA certificates that verify the broker (None: the system's).
    tls_ca: Path | None = None
    #: The first topic level(s): ``<prefix>/<gateway id>/...``.
    prefix: str = DEFAULT_PREFIX
    #: The QoS of everything published and subscribed (0 or 1).
    qos: int = 1
    #: Home Assistant's MQTT discovery: configs published, and republished on its birth.
    discovery: bool = True
    discovery_prefix: str = DISCOVERY_PREFIX
    #: The MQTT keepalive: the broker publishes the last will ("offline") about
    #: 1.5 keepalives after the gateway last spoke (plus its own check interval).
    keepalive_s: int = 30
    #: The JSON topics (state, availability, commands) and discovery.
    state_topics: bool = True
    #: Sparkplug B, or None.
    sparkplug: SparkplugConfig | None = None

    @property
    def url(self) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"{'mqtts' if self.tls else 'mqtt'}://{host}:{self.port}"


_DEFAULT: Final = MqttConfig(host="localhost", port=1883)


def parse_mqtt_section(table: ConfigTable, context: SectionContext) -> MqttConfig:
    """``[mqtt]`` (see the module docstring).

    Raises:
        GatewayConfigError: through *table*.
    """
    host, port, tls = _url(table)
    client_id = table.string("client_id")
    if client_id is not None and not client_id.strip():
        raise table.error("client_id", "expected a client id, got an empty string")
    username, password = table.string("username"), table.string("password")
    if password is not None and username is None:
        raise table.error("password", "a password needs a username")
    tls_ca = None
    if (ca := table.string("tls_ca")) is not None:
        tls_ca = context.base_dir / ca
        if not ca.strip() or not tls_ca.is_file():
            raise table.error("tls_ca", f"no such file: {str(tls_ca)!r}")
    qos = table.integer("qos")
    if qos is not None and qos not in (0, 1):
        raise table.error("qos", f"must be 0 or 1, got {qos}")
    keepalive_s = table.integer("keepalive_s")
    if keepalive_s is not None and not 1 <= keepalive_s <= 65535:
        raise table.error("keepalive_s", f"must be 1..65535 seconds, got {keepalive_s}")
    tls = tls or tls_ca is not None  # a CA to verify the broker with means TLS
    discovery = table.boolean("discovery")
    state_topics = table.boolean("state_topics")
    sparkplug = _sparkplug(table)
    if state_topics is False and sparkplug is None:
        raise table.error(
            "state_topics", "with state_topics = false, set sparkplug = true: nothing is published"
        )
    return MqttConfig(
        host=host,
        port=port if port is not None else _PORTS["mqtts" if tls else "mqtt"],
        tls=tls,
        client_id=client_id if client_id is not None else f"sj300-{context.gateway_id}",
        username=username,
        password=password,
        tls_ca=tls_ca,
        prefix=_topic_prefix(table, "prefix", DEFAULT_PREFIX),
        qos=_DEFAULT.qos if qos is None else qos,
        discovery=_DEFAULT.discovery if discovery is None else discovery,
        discovery_prefix=_topic_prefix(table, "discovery_prefix", DISCOVERY_PREFIX),
        keepalive_s=_DEFAULT.keepalive_s if keepalive_s is None else keepalive_s,
        state_topics=_DEFAULT.state_topics if state_topics is None else state_topics,
        sparkplug=sparkplug,
    )


def _sparkplug(table: ConfigTable) -> SparkplugConfig | None:
    """``sparkplug = true`` with its ``group_id`` and optional ``primary_host_id``."""
    enabled = table.boolean("sparkplug")
    if not enabled:
        for key in ("group_id", "primary_host_id"):
            if table.string(key) is not None:
                raise table.error(key, "needs sparkplug = true")
        return None
    group_id = _sparkplug_id(table, "group_id")
    if group_id is None:
        raise table.error("group_id", "sparkplug = true needs a group_id (the Sparkplug group)")
    return SparkplugConfig(
        group_id=group_id, primary_host_id=_sparkplug_id(table, "primary_host_id")
    )


def _sparkplug_id(table: ConfigTable, key: str) -> str | None:
    """A Sparkplug id: UTF-8 text without ``+``, ``/``, ``#`` or control characters."""
    text = table.string(key)
    if text is None:
        return None
    if not text or any(c in "+/#" or not c.isprintable() for c in text) or text != text.strip():
        raise table.error(
            key,
            f"expected a Sparkplug id: text without '+', '/', '#', control characters or "
            f"surrounding spaces, got {text!r}",
        )
    return text


def _url(table: ConfigTable) -> tuple[str, int | None, bool]:
    """``mqtt://HOST[:PORT]`` or ``mqtts://``: (host, port or None, TLS)."""
    text = table.required_string("url")
    expected = f"expected mqtt://HOST[:PORT] or mqtts://HOST[:PORT], got {text!r}"
    try:
        parts = urllib.parse.urlsplit(text.strip())
        port = parts.port
    except ValueError:  # a port that is not a number or out of 0..65535, a bad IPv6 literal
        raise table.error("url", expected) from None
    scheme = parts.scheme.lower()
    if scheme not in _PORTS or not parts.hostname:
        raise table.error("url", expected)
    if parts.username is not None or parts.password is not None:
        raise table.error("url", "give the credentials as username and password, not in the URL")
    if parts.path not in ("", "/") or parts.query or parts.fragment:
        raise table.error("url", expected)
    if port == 0:
        raise table.error("url", f"port must be 1..65535, got 0 in {text!r}")
    return parts.hostname, port, scheme == "mqtts"


def _topic_prefix(table: ConfigTable, name: str, default: str) -> str:
    """Topic levels (``sj300``, ``plant/sj300``): each a valid name, no wildcards."""
    prefix = table.string(name)
    if prefix is None:
        return default
    if not all(valid_name(level) for level in prefix.split("/")):
        raise table.error(
            name,
            "expected topic levels of letters, digits, '_', '.' and '-' separated by '/', "
            f"got {prefix!r}",
        )
    return prefix
