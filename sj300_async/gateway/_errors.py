"""The error of a gateway that cannot start a northbound (a configuration's own is in ``_toml``)."""

from __future__ import annotations

import os
import socket
from collections.abc import Sequence
from typing import Any

from ..wire import SJ300Error
from ._model import Endpoint

__all__ = ["GatewayStartError"]


class GatewayStartError(SJ300Error, OSError):
    """A northbound could not start: its port is in use, its address is not on this host...

    ``str()`` is one line naming the configuration section, where it was to
    listen, and why: ``modbus: cannot listen on 127.0.0.1:502: Address
    already in use``. An ``OSError`` like the one it replaces (its
    ``errno``; the northbound's own error is the ``__cause__``), so a caller
    that catches ``OSError`` still does.
    """

    def __init__(
        self, section: str, endpoints: Sequence[Endpoint], reason: str, errno: int | None = None
    ) -> None:
        where = " and ".join(map(str, endpoints))
        message = (
            f"{section}: cannot listen on {where}: {reason}" if where else f"{section}: {reason}"
        )
        super().__init__(errno, message)
        #: The northbound's configuration section (``"modbus"``, ``"metrics"``...).
        self.section = section
        #: Where it was configured to listen (empty: a northbound that does not listen).
        self.endpoints = tuple(endpoints)
        #: Why, in words (the system's words for the errno).
        self.reason = reason

    @classmethod
    def of(cls, section: str, endpoints: Sequence[Endpoint], exc: OSError) -> GatewayStartError:
        """The error of northbound *section*, which raised *exc* from its ``start``."""
        if isinstance(exc, socket.gaierror):  # its errno is a resolver's, not the system's
            reason = f"cannot resolve the address: {exc.strerror}"
        else:
            reason = os.strerror(exc.errno) if exc.errno else str(exc) or type(exc).__name__
        return cls(section, endpoints, reason, exc.errno)

    def __str__(self) -> str:
        return str(self.strerror)

    def __reduce__(self) -> tuple[Any, ...]:
        return (type(self), (self.section, self.endpoints, self.reason, self.errno))
