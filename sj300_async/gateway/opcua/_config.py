"""``[opcua]``: where the OPC UA server listens, its security, its certificate, its users.

::

    [opcua]
    endpoint = "opc.tcp://0.0.0.0:4840"
    # the default: both Basic256Sha256 modes; "None" only when named here
    security = ["Basic256Sha256_SignAndEncrypt", "Basic256Sha256_Sign"]
    certificate = "opcua/cert.der"     # generated at first start when missing
    private_key = "opcua/key.pem"
    trusted_clients = "opcua/trusted"  # optional: only these client certificates
    max_connections = 32               # the hardening's limits (docs/OPCUA.md, "Hardening")
    max_connections_per_address = 16
    max_unactivated_per_address = 4
    activate_within_s = 5.0
    login_burst = 5
    login_interval_s = 12.0
    max_monitored_items_per_session = 1000
    max_monitored_items_per_address = 2000
    nodeset_cache = "/var/cache/sj300"  # default: $CACHE_DIRECTORY, ~/.cache/sj300-async
    [[opcua.users]]
    name = "operator"
    password_hash = "scrypt$16384$8$1$..."   # sj300 gateway --hash-password

Decisions:

- **Secure by default.** Without ``security`` the server offers
  Basic256Sha256 with SignAndEncrypt and with Sign, and no unsecured
  endpoint; ``"None"`` must be named. A configuration naming only
  ``"None"`` serves reads, never writes (writes need an encrypted channel).
- **The certificate.** ``certificate`` and ``private_key`` (relative to
  the configuration file) default to ``opcua/cert.der`` and
  ``opcua/key.pem`` in the state directory: systemd's ``$STATE_DIRECTORY``
  when the gateway runs as its service (contrib/systemd), else beside the
  configuration file. When neither file exists, the first start generates a
  self-signed pair there (RSA 2048, SHA-256, ten years, the application
  URI and the host name in its subject alternative names) and says so;
  when one exists without the other, the configuration is refused. A
  user's own certificate is used as is: its application URI becomes the
  server's.
- **Client certificates.** With ``trusted_clients`` (a directory of DER or
  PEM certificates) only those clients may open a session; without it,
  any client certificate opens the encrypted channel, and the user's
  password is what authenticates (documented in docs/OPCUA.md).
- **Limits for what costs the server before a client proves anything**
  (issue 41; docs/OPCUA.md, "Hardening"): connections per client address
  (half of ``max_connections`` by default, as the HTTP and Modbus doors'
  ``max_connections_per_address``: one address never holds them all),
  sessions not yet activated per address and the time they have to
  activate (:mod:`._admission`), and each address's password budget
  (:mod:`._logins`: five at once, then five a minute, the HTTP door's).
  Each default is far above what a plant's clients do; a key tunes it,
  within bounds that keep it a limit.
- **The standard nodeset's cache** (``nodeset_cache``, a directory; ``""``
  turns it off): :mod:`._nodeset`.
- Port 0 picks a free port (the tests' way); the announce line names it.
"""

from __future__ import annotations

import urllib.parse
from dataclasses import dataclass
from pathlib import Path
from typing import Final

from .. import (
    ConfigTable,
    Endpoint,
    GatewayStartError,
    SectionContext,
    User,
    parse_users,
    unknown_choice,
)
from ._nodeset import default_cache

__all__ = [
    "DEFAULT_SECURITY",
    "OPCUA_KEYS",
    "SECURITY_MODES",
    "OpcuaConfig",
    "certificate_error",
    "parse_endpoint_url",
    "parse_opcua_section",
]

OPCUA_KEYS: Final = (
    *("endpoint", "security", "certificate", "private_key", "trusted_clients"),
    *("users", "namespace", "max_connections", "max_connections_per_address"),
    *("max_unactivated_per_address", "activate_within_s", "login_burst", "login_interval_s"),
    *("max_monitored_items_per_session", "max_monitored_items_per_address", "nodeset_cache"),
)
#: The security modes a configuration may name, strongest first.
SECURITY_MODES: Final = ("Basic256Sha256_SignAndEncrypt", "Basic256Sha256_Sign", "None")
DEFAULT_SECURITY: Final = SECURITY_MODES[:2]
DEFAULT_CERTIFICATE: Final = "opcua/cert.der"
DEFAULT_PRIVATE_KEY: Final = "opcua/key.pem"
#: Client connections at once, at most (more are refused at accept).
DEFAULT_MAX_CONNECTIONS: Final = 32
#: Sessions one client address may hold not yet activated, and the seconds a session has
#: to activate before it is closed (asyncua: unlimited, and as long as its connection).
DEFAULT_UNACTIVATED_PER_ADDRESS: Final = 4
DEFAULT_ACTIVATE_WITHIN_S: Final = 5.0
#: Password checks one client address may have at once, then one more every interval
#: (five a minute: the HTTP door's login budget).
DEFAULT_LOGIN_BURST: Final = 5
DEFAULT_LOGIN_INTERVAL_S: Final = 12.0
#: Monitored items one session may hold over its subscriptions, and one client address
#: over its sessions. Far above a drive's 30-odd variables, and what the subscription
#: probe measured (gateway/opcua/_subscriptions.py); a SCADA watching a large plant from
#: one host raises them.
DEFAULT_ITEMS_PER_SESSION: Final = 1_000
DEFAULT_ITEMS_PER_ADDRESS: Final = 2_000


@dataclass(frozen=True, slots=True)
class OpcuaConfig:
    """``[opcua]`` (see the module docstring)."""

    endpoint: Endpoint
    #: The endpoint's host as written (a name or an address), for the URL served.
    host_text: str
    security: tuple[str, ...] = DEFAULT_SECURITY
    certificate: Path = Path(DEFAULT_CERTIFICATE)
    private_key: Path = Path(DEFAULT_PRIVATE_KEY)
    trusted_clients: Path | None = None
    users: tuple[User, ...] = ()
    #: The namespace URI of the drives' nodes (default ``urn:sj300-async:<gateway id>``).
    namespace: str = ""
    max_connections: int = DEFAULT_MAX_CONNECTIONS
    #: Connections one client address may hold (default: half of max_connections).
    max_connections_per_address: int = DEFAULT_MAX_CONNECTIONS // 2
    max_unactivated_per_address: int = DEFAULT_UNACTIVATED_PER_ADDRESS
    activate_within_s: float = DEFAULT_ACTIVATE_WITHIN_S
    login_burst: int = DEFAULT_LOGIN_BURST
    login_interval_s: float = DEFAULT_LOGIN_INTERVAL_S
    max_monitored_items_per_session: int = DEFAULT_ITEMS_PER_SESSION
    max_monitored_items_per_address: int = DEFAULT_ITEMS_PER_ADDRESS
    #: Where the standard nodeset is kept between starts (None: not kept; :mod:`._nodeset`).
    nodeset_cache: Path | None = None

    @property
    def url(self) -> str:
        host = f"[{self.host_text}]" if ":" in self.host_text else self.host_text
        return f"opc.tcp://{host}:{self.endpoint.port}"

    @property
    def secure(self) -> bool:
        """Some endpoint encrypts (writes are possible at all)."""
        return "Basic256Sha256_SignAndEncrypt" in self.security


def certificate_error(certificate: Path, exc: Exception) -> GatewayStartError:
    """The start's error for a certificate pair that cannot be used (one line)."""
    return GatewayStartError("opcua", (), f"cannot use the certificate {certificate}: {exc}")


def parse_endpoint_url(text: str) -> tuple[str, int]:
    """``opc.tcp://HOST:PORT`` as (host, port).

    Raises:
        ValueError: not such a URL (the message says what is expected).
    """
    expected = f"expected opc.tcp://HOST:PORT, got {text!r}"
    try:
        parts = urllib.parse.urlsplit(text.strip())
        port = parts.port
    except ValueError:
        raise ValueError(expected) from None
    if parts.scheme.lower() != "opc.tcp" or not parts.hostname or port is None:
        raise ValueError(expected)
    if parts.username is not None or parts.password is not None:
        raise ValueError("an OPC UA endpoint carries no credentials: name [[opcua.users]]")
    if parts.path not in ("", "/") or parts.query or parts.fragment:
        raise ValueError(expected)
    return parts.hostname, port


def parse_opcua_section(table: ConfigTable, context: SectionContext) -> OpcuaConfig:
    """``[opcua]`` (see the module docstring).

    Raises:
        GatewayConfigError: through *table*.
    """
    try:
        host, port = parse_endpoint_url(table.required_string("endpoint"))
    except ValueError as exc:
        raise table.error("endpoint", str(exc)) from None
    security = _security(table)
    certificate, private_key = _key_pair(table, context)
    trusted = None
    if (text := table.string("trusted_clients")) is not None:
        trusted = context.base_dir / text
        if not text.strip() or not trusted.is_dir():
            raise table.error("trusted_clients", f"no such directory: {str(trusted)!r}")
    namespace = table.string("namespace")
    if namespace is not None and not namespace.strip():
        raise table.error("namespace", "expected a namespace URI, got an empty string")
    max_connections = _bounded(table, "max_connections", 1, 1000, DEFAULT_MAX_CONNECTIONS)
    per_address = _bounded(
        table, "max_connections_per_address", 1, max_connections, max(1, max_connections // 2)
    )
    unactivated = _bounded(
        table, "max_unactivated_per_address", 1, 100, DEFAULT_UNACTIVATED_PER_ADDRESS
    )
    login_burst = _bounded(table, "login_burst", 1, 100, DEFAULT_LOGIN_BURST)
    activate_within_s = _seconds(table, "activate_within_s", 0.5, 60.0, DEFAULT_ACTIVATE_WITHIN_S)
    login_interval_s = _seconds(table, "login_interval_s", 0.1, 3600.0, DEFAULT_LOGIN_INTERVAL_S)
    items_per_session = _bounded(
        table, "max_monitored_items_per_session", 1, 100_000, DEFAULT_ITEMS_PER_SESSION
    )
    items_per_address = _bounded(
        table, "max_monitored_items_per_address", 1, 100_000, DEFAULT_ITEMS_PER_ADDRESS
    )
    cache: Path | None = default_cache()
    if (text := table.string("nodeset_cache")) is not None:
        cache = context.base_dir / text if text.strip() else None
    return OpcuaConfig(
        endpoint=Endpoint(host, port),
        host_text=host,
        security=security,
        certificate=certificate,
        private_key=private_key,
        trusted_clients=trusted,
        users=parse_users(table),
        namespace=namespace or f"urn:sj300-async:{context.gateway_id}",
        max_connections=max_connections,
        max_connections_per_address=per_address,
        max_unactivated_per_address=unactivated,
        activate_within_s=activate_within_s,
        login_burst=login_burst,
        login_interval_s=login_interval_s,
        max_monitored_items_per_session=items_per_session,
        max_monitored_items_per_address=items_per_address,
        nodeset_cache=cache,
    )


def _bounded(table: ConfigTable, key: str, low: int, high: int, default: int) -> int:
    """An integer key within low..high (*default* when absent)."""
    value = table.integer(key)
    if value is None:
        return default
    if not low <= value <= high:
        raise table.error(key, f"must be {low}..{high}, got {value}")
    return value


def _seconds(table: ConfigTable, key: str, low: float, high: float, default: float) -> float:
    """A number of seconds within low..high (*default* when absent)."""
    value = table.number(key, minimum=low, inclusive=True)
    if value is None:
        return default
    if value > high:
        raise table.error(key, f"must be {low:g}..{high:g} s, got {value:g}")
    return value


def _security(table: ConfigTable) -> tuple[str, ...]:
    modes = table.strings("security")
    if modes is None:
        return DEFAULT_SECURITY
    if not modes:
        raise table.error("security", "name at least one security mode")
    for mode in modes:
        if mode not in SECURITY_MODES:
            raise table.error("security", unknown_choice("security mode", mode, SECURITY_MODES))
    if len(set(modes)) != len(modes):
        raise table.error("security", "a security mode is named twice")
    return tuple(mode for mode in SECURITY_MODES if mode in modes)


def _key_pair(table: ConfigTable, context: SectionContext) -> tuple[Path, Path]:
    """The pair's paths: as given, relative to the file; by default in the state directory
    (``$STATE_DIRECTORY`` under systemd, else beside the file)."""
    paths = []
    for key, default in (
        ("certificate", DEFAULT_CERTIFICATE),
        ("private_key", DEFAULT_PRIVATE_KEY),
    ):
        text = table.string(key)
        if text is not None and not text.strip():
            raise table.error(key, "expected a file name, got an empty string")
        paths.append(context.state / default if text is None else context.base_dir / text)
    certificate, private_key = paths
    if certificate.exists() != private_key.exists():
        missing = "private_key" if certificate.exists() else "certificate"
        raise table.error(
            missing,
            f"{certificate} and {private_key}: both exist or neither (then both are generated)",
        )
    return certificate, private_key
