"""The registries: a protocol's name → its dialect, a URL scheme → its connector.

Nothing in the bus names a protocol's package: a bus URL's ``protocol=``
(or ``open_bus(..., protocol=...)``) is looked up here, and the dialect's
module is imported only then, so a protocol that is not used costs nothing
(python-can finds its interfaces the same way). Adding a protocol is one
package with a dialect plus one entry: in :data:`_BUILT_IN` for the
library's own, or :func:`register_protocol` for anyone else's.

Nor does the bus name the simulator: a URL scheme whose line is no real
one (``sim://``) is looked up in :data:`_SCHEME_CONNECTORS`, whose entry is
imported when such a bus is opened (:func:`scheme_connector`). Real lines
(``tcp``, ``rfc2217``, ``serial``) are opened by the transports below the
bus, and ``replay://`` by the bus itself from the capture.
"""

from __future__ import annotations

import importlib
import re
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Final, Protocol

from ..wire import LineSettings, LocalProtocolError
from ._dialect import Dialect

if TYPE_CHECKING:
    from ..transports import LineFaults
    from ._link import Connector
    from ._url import BusAddress

__all__ = [
    "DEFAULT_PROTOCOL",
    "SchemeConnection",
    "SchemeConnector",
    "get_dialect",
    "load_object",
    "protocol_names",
    "register_protocol",
    "scheme_connector",
]

AnyDialect = Dialect[Any, Any]

#: The protocol a bus speaks when nobody says.
DEFAULT_PROTOCOL: Final = "sj300"

#: The library's protocols: name → ``"module:attribute"`` of a configured-by-default dialect.
_BUILT_IN: Final = {
    "sj300": "sj300_async.sj300._dialect:SJ300_DIALECT",
    "fr700": "sj300_async.fr700._dialect:FR700_DIALECT",
}

_NAME = re.compile(r"[a-z][a-z0-9_]*\Z")
_entries: dict[str, str | Callable[[], AnyDialect]] = dict(_BUILT_IN)
_loaded: dict[str, AnyDialect] = {}


def register_protocol(name: str, dialect: str | Callable[[], AnyDialect]) -> None:
    """Make *name* a protocol a bus can speak.

    Args:
        name: lower-case letters, digits and ``_``, e.g. ``"modbus_ascii"``.
        dialect: ``"module:attribute"`` of a dialect object, imported on first
            use, or a callable returning the dialect.

    Raises:
        LocalProtocolError: a bad name, or one already registered.
    """
    if not isinstance(name, str) or not _NAME.match(name):
        raise LocalProtocolError(f"a protocol name is lower-case letters and digits, got {name!r}")
    if name in _entries:
        raise LocalProtocolError(f"protocol {name!r} is already registered")
    _entries[name] = dialect


def unregister_protocol(name: str) -> None:
    """Forget a protocol added with :func:`register_protocol` (the built-in ones stay)."""
    if name not in _BUILT_IN:
        _entries.pop(name, None)
        _loaded.pop(name, None)


def protocol_names() -> tuple[str, ...]:
    """The names of every registered protocol."""
    return tuple(_entries)


def get_dialect(name: str) -> AnyDialect:
    """The default dialect of protocol *name*.

    Raises:
        LocalProtocolError: no such protocol.
    """
    dialect = _loaded.get(name)
    if dialect is not None:
        return dialect
    entry = _entries.get(name) if isinstance(name, str) else None
    if entry is None:
        raise LocalProtocolError(f"unknown protocol {name!r} (use {' or '.join(sorted(_entries))})")
    loaded: AnyDialect = load_object(entry) if isinstance(entry, str) else entry()
    if loaded.name != name:
        raise LocalProtocolError(f"protocol {name!r} is registered to dialect {loaded.name!r}")
    _loaded[name] = loaded
    return loaded


def load_object(path: str) -> Any:
    """Import ``"package.module:attribute"`` and return the attribute."""
    module_name, _, attribute = path.partition(":")
    return getattr(importlib.import_module(module_name), attribute)


# -- URL schemes ---------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class SchemeConnection:
    """What a :class:`SchemeConnector` gives the bus: how to connect, and who serves the line."""

    #: Opens the transport, on the first connection and on every reconnection.
    connector: Connector
    #: What serves the line, for ``bus.simulator`` (the simulated drives on ``sim://``).
    simulator: Any = None


class SchemeConnector(Protocol):
    """Builds the connection of a URL scheme that is no real line: :data:`_SCHEME_CONNECTORS`."""

    def __call__(
        self,
        address: BusAddress,
        *,
        line: LineSettings,
        dialect: AnyDialect,
        faults: tuple[LineFaults | None, LineFaults | None] | None,
        simulator: Any,
    ) -> SchemeConnection:
        """The connection of the bus at *address*; called once per bus, before it connects.

        Args:
            address: the parsed URL (its nodes and the scheme's options in
                ``sim_options``).
            line: the line settings of the bus (a speed of 0 is an instant line).
            dialect: the protocol the bus speaks, configured.
            faults: ``open_bus``'s (to-drive, to-host) line faults, or None.
            simulator: ``open_bus``'s ``simulator=``, or None.

        Raises:
            LocalProtocolError: a bad option of the scheme, or a *simulator*
                that does not fit the protocol (nothing is opened).
        """
        ...


#: URL schemes that are no real line: scheme → ``"module:attribute"`` of its
#: :class:`SchemeConnector`, imported when a bus with such a URL is opened.
_SCHEME_CONNECTORS: Final = {
    "sim": "sj300_async.simulator._sim_connector:sim_connector",
}


def scheme_connector(scheme: str) -> SchemeConnector | None:
    """The connector of URL scheme *scheme*, imported on first use; None for a real line."""
    entry = _SCHEME_CONNECTORS.get(scheme)
    if entry is None:
        return None
    found: SchemeConnector = load_object(entry)
    return found
