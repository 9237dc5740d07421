"""``open_bus`` for users: the neutral one, with each built-in protocol's types.

:func:`sj300_async.bus.open_bus` does the work; these overloads tell a type
checker that ``open_bus(url)`` gives SJ300 drives and
``open_bus(url, protocol="fr700")`` FR-700 ones. Another registered
protocol's bus is a ``Bus[Any, Any]``. A URL that names the protocol only in
its query is typed by the ``protocol`` argument, so code that wants FR-700
types passes it (the two must agree).
"""

from __future__ import annotations

from contextlib import AbstractAsyncContextManager
from os import PathLike
from typing import Any, Literal, overload

from .bus import Bus, BusTiming, CaptureFile, Dialect, ReconnectPolicy, TraceHook
from .bus import open_bus as _open_bus
from .fr700 import Fr700Drive
from .sj300 import Broadcast, Drive
from .transports import LineFaults
from .wire import LineSettings

__all__ = ["open_bus"]


@overload
def open_bus(
    url: str,
    *,
    protocol: Literal["fr700"],
    timeout: float | None = None,
    deadline: float | None = None,
    retries: int = 2,
    strip_echo: bool | None = None,
    read_only: bool = False,
    line: LineSettings | None = None,
    timing: BusTiming | None = None,
    trace: TraceHook | None = None,
    reconnect: ReconnectPolicy | None = None,
    faults: tuple[LineFaults | None, LineFaults | None] | None = None,
    simulator: Any = None,
    dialect: Dialect[Any, Any] | None = None,
    capture: str | PathLike[str] | CaptureFile | None = None,
) -> AbstractAsyncContextManager[Bus[Fr700Drive, None]]: ...


@overload
def open_bus(
    url: str,
    *,
    protocol: Literal["sj300"] | None = None,
    timeout: float | None = None,
    deadline: float | None = None,
    retries: int = 2,
    strip_echo: bool | None = None,
    read_only: bool = False,
    line: LineSettings | None = None,
    timing: BusTiming | None = None,
    trace: TraceHook | None = None,
    reconnect: ReconnectPolicy | None = None,
    faults: tuple[LineFaults | None, LineFaults | None] | None = None,
    simulator: Any = None,
    dialect: Dialect[Any, Any] | None = None,
    capture: str | PathLike[str] | CaptureFile | None = None,
) -> AbstractAsyncContextManager[Bus[Drive, Broadcast]]: ...


@overload
def open_bus(
    url: str,
    *,
    protocol: str,
    timeout: float | None = None,
    deadline: float | None = None,
    retries: int = 2,
    strip_echo: bool | None = None,
    read_only: bool = False,
    line: LineSettings | None = None,
    timing: BusTiming | None = None,
    trace: TraceHook | None = None,
    reconnect: ReconnectPolicy | None = None,
    faults: tuple[LineFaults | None, LineFaults | None] | None = None,
    simulator: Any = None,
    dialect: Dialect[Any, Any] | None = None,
    capture: str | PathLike[str] | CaptureFile | None = None,
) -> AbstractAsyncContextManager[Bus[Any, Any]]: ...


def open_bus(url: str, **kwargs: Any) -> AbstractAsyncContextManager[Bus[Any, Any]]:
    """Open a bus (see :func:`sj300_async.bus.open_bus` for the arguments and errors)."""
    return _open_bus(url, **kwargs)


open_bus.__doc__ = _open_bus.__doc__
