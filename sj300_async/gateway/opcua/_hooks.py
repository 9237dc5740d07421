"""Every place the OPC UA northbound reaches past asyncua's public API, in one module.

asyncua's server has no public way to do three things the gateway needs,
so they are done here, each on the one server instance, and checked by
``tests/opcua/test_opcua_hooks.py`` against the installed asyncua (the
``opcua`` extra pins the major version):

- **A ruleset per security mode.** The server gives every endpoint's
  policy factory the same permission ruleset; the handlers need to know
  the mode of the channel a request came by, so each factory gets a
  ruleset of its own mode (:func:`rules_per_mode`).
- **Sessions closing.** A connection-scoped lease lapses when its OPC UA
  session closes (CloseSession, its timeout, or the transport lost with no
  subscription left): the server's unregistering of an external session is
  wrapped (:func:`on_session_closed`).
- **Writes that wait for the line.** asyncua's write service stores a
  value and returns; a parameter write must go to the drive and answer
  with what became of it. The attribute service is wrapped
  (:func:`route_writes`): writes to the gateway's namespace go to the
  northbound's handler (awaited, one status per node), the rest to asyncua.
"""

from __future__ import annotations

from collections.abc import Awaitable, Callable
from typing import Any

from asyncua import Server, ua
from asyncua.crypto.permission_rules import PermissionRuleset

__all__ = ["on_session_closed", "route_writes", "rules_per_mode"]

WriteHandler = Callable[[ua.WriteValue, Any], Awaitable[ua.StatusCode]]


def rules_per_mode(
    server: Server, rules: Callable[[ua.MessageSecurityMode], PermissionRuleset]
) -> None:
    """Give each endpoint's policy factory the ruleset of its own security mode."""
    for factory in server._policies:
        factory.permission_ruleset = rules(factory.mode)


def on_session_closed(server: Server, closed: Callable[[Any], None]) -> None:
    """Call *closed* with each external session's user as the session closes."""
    iserver = server.iserver
    unregister = iserver.unregister_external_session

    def unregistered(session: Any) -> None:
        unregister(session)
        closed(session.user)

    iserver.unregister_external_session = unregistered


class _RoutedWrites:
    """asyncua's attribute service, with the gateway's namespace's writes handed over."""

    def __init__(self, inner: Any, namespace: int, handler: WriteHandler) -> None:
        self._inner = inner
        self._namespace = namespace
        self._handler = handler

    def __getattr__(self, name: str) -> Any:
        return getattr(self._inner, name)

    async def write(self, params: ua.WriteParameters, user: Any = None) -> list[ua.StatusCode]:
        ours = [value.NodeId.NamespaceIndex == self._namespace for value in params.NodesToWrite]
        if not any(ours):
            return list(await self._inner.write(params, user=user))
        results: list[ua.StatusCode] = []
        for value, own in zip(params.NodesToWrite, ours, strict=True):
            if own:
                results.append(await self._handler(value, user))
            else:
                single = ua.WriteParameters(NodesToWrite=[value])
                results.extend(await self._inner.write(single, user=user))
        return results


def route_writes(server: Server, namespace: int, handler: WriteHandler) -> None:
    """Hand every write to a node of *namespace* to *handler* (see the module docstring)."""
    iserver = server.iserver
    iserver.attribute_service = _RoutedWrites(iserver.attribute_service, namespace, handler)
