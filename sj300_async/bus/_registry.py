"""The protocol registry: a protocol's name → its dialect, imported on first use.

Nothing in the bus names a protocol's package: a bus URL's ``protocol=``
(or ``open_bus(..., protocol=...)``) is looked up here, and the dialect's
module is imported only then, so a protocol that is not used costs nothing
(python-can finds its interfaces the same way). Adding a protocol is one
package with a dialect plus one entry: in :data:`_BUILT_IN` for the
library's own, or :func:`register_protocol` for anyone else's.
"""

from __future__ import annotations

import importlib
import re
from collections.abc import Callable
from typing import Any, Final

from ..wire import LocalProtocolError
from ._dialect import Dialect

__all__ = ["DEFAULT_PROTOCOL", "get_dialect", "load_object", "protocol_names", "register_protocol"]

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
