"""``open_bus`` for users: the neutral one, with each built-in protocol's types.

:func:`sj300_async.bus.open_bus` does the work; these overloads tell a type
checker that ``open_bus(url)`` gives SJ300 drives and
``open_bus(url, protocol="fr700")`` FR-700 ones. Another registered
protocol's bus is a ``Bus[Any, Any]``. The types follow the ``protocol``
argument, so the bus must speak that protocol: a URL whose ``protocol=``
names another one (``open_bus("sim://?protocol=fr700")``, typed SJ300) is
refused before anything is opened, and so is a ``replay://`` capture of
another protocol. The neutral :func:`sj300_async.bus.open_bus`, typed
``Bus[Any, Any]``, takes the protocol from the URL.
"""

from __future__ import annotations

from contextlib import AbstractAsyncContextManager
from typing import Any, Literal, overload

from typing_extensions import Unpack

from .bus import DEFAULT_PROTOCOL, Bus, BusOptions, url_protocol
from .bus import open_bus as _open_bus
from .fr700 import Fr700Drive
from .sj300 import Broadcast, Drive
from .wire import LocalProtocolError

__all__ = ["open_bus"]


@overload
def open_bus(
    url: str, *, protocol: Literal["fr700"], **options: Unpack[BusOptions]
) -> AbstractAsyncContextManager[Bus[Fr700Drive, None]]: ...


@overload
def open_bus(
    url: str, *, protocol: Literal["sj300"] | None = None, **options: Unpack[BusOptions]
) -> AbstractAsyncContextManager[Bus[Drive, Broadcast]]: ...


@overload
def open_bus(
    url: str, *, protocol: str, **options: Unpack[BusOptions]
) -> AbstractAsyncContextManager[Bus[Any, Any]]: ...


def open_bus(
    url: str, *, protocol: str | None = None, **options: Unpack[BusOptions]
) -> AbstractAsyncContextManager[Bus[Any, Any]]:
    """Open a bus that speaks *protocol*, as its type says (the docstring is the neutral one's).

    Raises:
        LocalProtocolError: the URL names another protocol (at once); the
            rest as :func:`sj300_async.bus.open_bus`.
    """
    typed = DEFAULT_PROTOCOL if protocol is None else protocol
    named = url_protocol(url)
    if named is not None and named != typed:
        raise LocalProtocolError(
            f"{url} names protocol={named} but open_bus is typed for {typed}: "
            f"pass protocol={named!r} so that the types follow the URL"
        )
    # Named, always: a replay:// capture of another protocol is refused too.
    return _open_bus(url, protocol=typed, **options)


open_bus.__doc__ = _open_bus.__doc__
