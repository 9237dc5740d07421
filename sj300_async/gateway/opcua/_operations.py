"""How many operations one request of a client may hold (issue 44's probe).

asyncua advertises 10,000 nodes per Read, Write, Browse, call... in the
Server object's ``OperationLimits`` and enforces none of them: a Read is
served in one turn of the event loop however many nodes it names, and a
4 MiB request names some 45,000. The probe of the lazy address space
measured one anonymous Read of 30,000 nodes holding the loop 0.7-0.9 s
with every node made at start and 1.7-2.6 s with drive nodes made as
asked (each made costs some 20 us): the poll, the leases and the stops
wait that long. (Figures in the CHANGELOG.)

So each service's operations per request are limited to
:data:`MAX_OPERATIONS`, advertised in ``OperationLimits`` (a client that
reads them, as node-opcua's does, splits its requests), and a request
over it is answered ``BadTooManyOperations`` as OPC UA Part 4 says, before
asyncua looks at any of its nodes, counted
(``sj300_opcua_refused_requests_total{reason="too_many_operations"}``).
1,000 is what servers commonly allow, 35 variables a drive means 28 drives
a Read, and a Read of 1,000 nodes none of which was made holds the loop
some 25 ms.

The gateway's own requests (its internal session, which adds the nodes at
start) are not limited. Patched on asyncua's ``InternalSession`` once per
process, acting on the sessions of the servers handed to
:func:`limit_operations` only.
"""

from __future__ import annotations

import weakref
from collections.abc import Callable
from typing import Any, Final

from asyncua import Server, ua
from asyncua.common.utils import ServiceError
from asyncua.server.internal_session import InternalSession

__all__ = ["MAX_OPERATIONS", "limit_operations"]

#: Operations (nodes, items, calls) one request of a client may hold, in every service.
MAX_OPERATIONS: Final = 1_000
_LIMIT_NODES: Final = tuple(
    getattr(ua.ObjectIds, f"Server_ServerCapabilities_OperationLimits_{name}")
    for name in (
        "MaxNodesPerRead", "MaxNodesPerHistoryReadData", "MaxNodesPerHistoryReadEvents",
        "MaxNodesPerWrite", "MaxNodesPerHistoryUpdateData", "MaxNodesPerHistoryUpdateEvents",
        "MaxNodesPerMethodCall", "MaxNodesPerBrowse", "MaxNodesPerRegisterNodes",
        "MaxNodesPerTranslateBrowsePathsToNodeIds", "MaxNodesPerNodeManagement",
        "MaxMonitoredItemsPerCall",
    )
)  # fmt: skip
#: Each service of a session: how to count its request's operations.
_COUNTED: Final[dict[str, Callable[[Any], Any]]] = {
    "read": lambda p: p.NodesToRead,
    "history_read": lambda p: p.NodesToRead,
    "write": lambda p: p.NodesToWrite,
    "history_update": lambda p: p.HistoryUpdateDetails,
    "browse": lambda p: p.NodesToBrowse,
    "browse_next": lambda p: p.ContinuationPoints,
    "register_nodes": lambda p: p,
    "unregister_nodes": lambda p: p,
    "translate_browsepaths_to_nodeids": lambda p: p,
    "add_nodes": lambda p: p,
    "delete_nodes": lambda p: p.NodesToDelete,
    "add_references": lambda p: p,
    "delete_references": lambda p: p,
    "call": lambda p: p,
    "create_monitored_items": lambda p: p.ItemsToCreate,
    "modify_monitored_items": lambda p: p.ItemsToModify,
    "delete_monitored_items": lambda p: p.MonitoredItemIds,
    "set_monitoring_mode": lambda p: p.MonitoredItemIds,
}
#: The servers limited, each with what it counts its refusals in.
_limited: weakref.WeakKeyDictionary[Any, Callable[[], None]] = weakref.WeakKeyDictionary()


async def limit_operations(server: Server, refused: Callable[[], None]) -> None:
    """Limit each request of *server*'s clients to :data:`MAX_OPERATIONS` operations and
    advertise it; *refused* is called for each request refused."""
    _patch()
    _limited[server.iserver] = refused
    for node in _LIMIT_NODES:
        await server.get_node(ua.NodeId(node)).write_value(
            ua.Variant(MAX_OPERATIONS, ua.VariantType.UInt32)
        )


def _patch() -> None:
    if getattr(InternalSession, "_sj300_limited", False):
        return
    for name, count in _COUNTED.items():
        setattr(InternalSession, name, _limited_method(getattr(InternalSession, name), count))
    InternalSession._sj300_limited = True


def _limited_method(method: Callable[..., Any], count: Callable[[Any], Any]) -> Any:
    async def limited(self: Any, params: Any, *args: Any, **kwargs: Any) -> Any:
        refused = _limited.get(self.iserver) if self.external else None
        if refused is not None:
            operations = count(params)
            if operations is not None and len(operations) > MAX_OPERATIONS:
                refused()
                raise ServiceError(ua.StatusCodes.BadTooManyOperations)
        return await method(self, params, *args, **kwargs)

    limited.__name__ = method.__name__
    limited.__doc__ = method.__doc__
    return limited
