"""The broker a northbound connects to: its URL, identity, credentials and TLS.

Both MQTT northbounds (``[mqtt]``, the JSON topics and Home Assistant;
``[sparkplug]``, Sparkplug B) take these keys in their own section, parsed
here once (:func:`parse_broker`) so they mean the same in both:

- ``url``: ``mqtt://HOST[:PORT]`` or ``mqtts://`` (ports 1883 and 8883 by
  default). Credentials have their own keys, ``username`` and ``password``:
  a URL ends up in logs.
- ``tls_ca``: the CA certificates that verify the broker (default: the
  system's). ``tls_cert`` and ``tls_key``: the client's certificate chain
  and private key (PEM), for a broker that authenticates clients by
  certificate (AWS IoT Core, Azure IoT Hub, Mosquitto's
  ``require_certificate``); one without the other is an error. Any of the
  three means TLS. Each must exist now, relative to the configuration
  file: a missing file found at connect time would be a retry loop, not an
  error.
- ``client_id`` (the section's default), ``keepalive_s`` (1..65535, 30).
"""

from __future__ import annotations

import dataclasses
import ssl
import urllib.parse
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Final

from .. import ConfigTable, SectionContext

__all__ = [
    "BROKER_KEYS",
    "BrokerConfig",
    "broker_fields",
    "load_client_certificate",
    "parse_broker",
]

#: The keys of a section that names a broker (each northbound adds its own).
BROKER_KEYS: Final = (
    *("url", "client_id", "username", "password"),
    *("tls_ca", "tls_cert", "tls_key", "keepalive_s"),
)
_PORTS: Final = {"mqtt": 1883, "mqtts": 8883}
DEFAULT_KEEPALIVE_S: Final = 30


@dataclass(frozen=True, slots=True)
class BrokerConfig:
    """A broker and how to connect to it (see the module docstring)."""

    host: str
    port: int
    #: TLS: an ``mqtts://`` URL, or a ``tls_ca`` / ``tls_cert`` given.
    tls: bool = False
    #: The MQTT client id (each section's default: ``sj300-<gateway id>``, ``…-spb``).
    client_id: str = "sj300"
    username: str | None = None
    password: str | None = field(default=None, repr=False)
    #: The CA certificates that verify the broker (None: the system's).
    tls_ca: Path | None = None
    #: The client's certificate chain (PEM), for a broker that asks for one.
    tls_cert: Path | None = None
    #: The client certificate's private key (PEM).
    tls_key: Path | None = None
    #: The MQTT keepalive: the broker publishes the last will about 1.5
    #: keepalives after the client last spoke (plus its own check interval).
    keepalive_s: int = DEFAULT_KEEPALIVE_S

    @property
    def url(self) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"{'mqtts' if self.tls else 'mqtt'}://{host}:{self.port}"


def broker_fields(broker: BrokerConfig) -> dict[str, Any]:
    """*broker*'s fields by name, to build a section's config that extends it."""
    return {f.name: getattr(broker, f.name) for f in dataclasses.fields(BrokerConfig)}


def parse_broker(table: ConfigTable, context: SectionContext, *, client_id: str) -> BrokerConfig:
    """The broker keys of *table* (see the module docstring); *client_id*: the default.

    Raises:
        GatewayConfigError: through *table*.
    """
    host, port, tls = _url(table)
    given_id = table.string("client_id")
    if given_id is not None and not given_id.strip():
        raise table.error("client_id", "expected a client id, got an empty string")
    username, password = table.string("username"), table.string("password")
    if password is not None and username is None:
        raise table.error("password", "a password needs a username")
    tls_ca = _pem(table, context, "tls_ca")
    tls_cert, tls_key = _pem(table, context, "tls_cert"), _pem(table, context, "tls_key")
    if (tls_cert is None) != (tls_key is None):
        given, missing = ("tls_cert", "tls_key") if tls_key is None else ("tls_key", "tls_cert")
        raise table.error(given, f"{given} needs {missing}: a certificate and its private key")
    if tls_cert is not None:
        _check_pair(table, tls_cert, tls_key)
    keepalive_s = table.integer("keepalive_s")
    if keepalive_s is not None and not 1 <= keepalive_s <= 65535:
        raise table.error("keepalive_s", f"must be 1..65535 seconds, got {keepalive_s}")
    # A CA to verify the broker with, or a certificate to show it, means TLS.
    tls = tls or tls_ca is not None or tls_cert is not None
    return BrokerConfig(
        host=host,
        port=port if port is not None else _PORTS["mqtts" if tls else "mqtt"],
        tls=tls,
        client_id=client_id if given_id is None else given_id,
        username=username,
        password=password,
        tls_ca=tls_ca,
        tls_cert=tls_cert,
        tls_key=tls_key,
        keepalive_s=DEFAULT_KEEPALIVE_S if keepalive_s is None else keepalive_s,
    )


def _pem(table: ConfigTable, context: SectionContext, key: str) -> Path | None:
    """A PEM file's path, relative to the configuration file; it must exist now."""
    text = table.string(key)
    if text is None:
        return None
    path = context.base_dir / text
    if not text.strip() or not path.is_file():
        raise table.error(key, f"no such file: {str(path)!r}")
    return path


def load_client_certificate(context: ssl.SSLContext, cert: Path, key: Path | None) -> None:
    """The client's certificate and key into *context*.

    A key encrypted with a passphrase is refused (ValueError), never asked for:
    OpenSSL would prompt on the terminal, blocking the event loop at every
    connection attempt. The key is kept unencrypted, readable by the gateway's
    user only (docs/GATEWAY.md).

    Raises:
        OSError: a file cannot be read, or the pair does not load (ssl.SSLError).
        ValueError: the key is encrypted.
    """
    context.load_cert_chain(str(cert), None if key is None else str(key), password=_no_passphrase)


def _no_passphrase() -> str:
    raise ValueError("the key is encrypted: give the gateway an unencrypted key file")


def _check_pair(table: ConfigTable, cert: Path, key: Path | None) -> None:
    """The certificate and key load together now: a mismatch would fail every attempt."""
    try:
        load_client_certificate(ssl.create_default_context(), cert, key)
    except (OSError, ValueError) as exc:  # ssl.SSLError is an OSError
        raise table.error("tls_cert", f"cannot load the certificate and key: {exc}") from None


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
