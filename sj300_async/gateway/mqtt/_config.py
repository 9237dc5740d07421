"""``[mqtt]``: the broker the gateway publishes to, and how.

The URL is ``mqtt://HOST[:PORT]`` or ``mqtts://`` (ports 1883 and 8883 by
default); credentials have their own keys (a URL ends up in logs). A
``tls_ca`` must exist now: a missing file found at connect time would be a
retry loop, not an error. A relative ``tls_ca`` is relative to the
configuration file. The client id defaults to ``sj300-<gateway id>``.
"""

from __future__ import annotations

import urllib.parse
from dataclasses import dataclass, field
from pathlib import Path
from typing import Final

from .. import ConfigTable, SectionContext, valid_name
from ._topics import DEFAULT_PREFIX, DISCOVERY_PREFIX

__all__ = ["MQTT_KEYS", "MqttConfig", "parse_mqtt_section"]

MQTT_KEYS: Final = (
    *("url", "client_id", "username", "password", "tls_ca", "prefix", "qos"),
    *("discovery", "discovery_prefix", "keepalive_s"),
)
_PORTS: Final = {"mqtt": 1883, "mqtts": 8883}


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
    )


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
