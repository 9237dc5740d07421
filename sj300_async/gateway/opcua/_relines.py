"""The lines and drives of the address space: made at start, added and removed by a reload.

At start :meth:`~._server.OpcuaServer._build` makes every line's object and
its drives (:func:`gather_lines`, then :func:`finish_lines` once the eager
nodes are committed). A reload that adds or removes lines (:mod:`..._reload`)
changes the address space on the running server, its sessions and
subscriptions kept:

- **added**: the same two steps for the new lines; a drive of a shape
  already served (its profile, parameters and grants) is listed at once and
  made when looked up, as at start; a new shape gathers its prototype first;
- **removed**: the line's drives are forgotten (no more made), then every
  node of the line (its object, properties, counters and each drive's nodes
  made so far) is deleted through asyncua's node management, which tells
  each monitored item on a deleted variable ``BadNodeIdUnknown``; the Lines
  folder's reference to it goes, and so do the server's bindings, writable
  parameters and method handlers of its drives.

Node ids are paths (``hall/Drive3/OutputFrequency``): a line's nodes are
those whose id is its name or starts with it and a slash. This module is
the server's friend: it keeps the maps :class:`~._server.OpcuaServer` serves
from.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from dataclasses import dataclass, field
from datetime import UTC, datetime
from typing import TYPE_CHECKING

from asyncua import Server, ua
from asyncua.common.manage_nodes import delete_nodes

from .. import GatewayDrive, ServedLine
from ._lazy import LazyNodes, make_shape
from ._model import DriveNodes, LineNodes, build_drive, build_line, drive_identity, shape_key
from ._space import SpaceBuilder
from ._speedups import ServedDataValue, push_frozen

if TYPE_CHECKING:
    from ._server import OpcuaServer

__all__ = ["Gathered", "add_lines", "finish_lines", "gather_lines", "remove_line"]


@dataclass
class Gathered:
    """Lines gathered into a space builder, waiting for its commit."""

    lines: list[LineNodes] = field(default_factory=list)
    drives: list[DriveNodes] = field(default_factory=list)
    #: Lazy: each drive's shape and line object; the new shapes' prototypes.
    listed: list[tuple[object, GatewayDrive, LineNodes]] = field(default_factory=list)
    prototypes: dict[object, tuple[list[ua.AddNodesItem], str, ua.NodeId]] = field(
        default_factory=dict
    )


def gather_lines(
    owner: OpcuaServer, space: SpaceBuilder, folder: ua.NodeId, lines: Sequence[ServedLine]
) -> Gathered:
    """The objects of *lines* and their drives, gathered into *space* under *folder* (lazy:
    one drive per new shape gathers its nodes, the prototype; the others only ids)."""
    gathered = Gathered()
    for line in lines:
        line_nodes = build_line(space, folder, line)
        gathered.lines.append(line_nodes)
        for drive in line.drives.values():
            control = line.config.control_allowed(drive.node)
            own = space
            if owner._lazy:
                key = shape_key(drive, control=control)
                new = key not in owner._shapes and key not in gathered.prototypes
                own = SpaceBuilder(owner.namespace, gather=new)
                gathered.listed.append((key, drive, line_nodes))
            built = build_drive(own, line_nodes.node, line.config.name, drive, control=control)
            owner._drives[drive.key] = built
            gathered.drives.append(built)
            if own.gather and own is not space:
                gathered.prototypes[key] = (own.items, str(built.node.Identifier), line_nodes.node)
    return gathered


def finish_lines(owner: OpcuaServer, server: Server, gathered: Gathered) -> None:
    """After the commit: the new shapes made, the drives listed, every value bound."""
    table = owner._table
    if table is not None:
        aspace = server.iserver.aspace
        for key, prototype in gathered.prototypes.items():
            owner._shapes[key] = make_shape(aspace, *prototype)
        for key, drive, line_nodes in gathered.listed:
            identity = functools.partial(drive_identity, drive, line_nodes.line.config.name)
            table.add_drive(owner._shapes[key], identity, line_nodes.node)
    for line_nodes in gathered.lines:
        owner._lines.append(line_nodes)
        owner._bind_counters(server, line_nodes)
    for nodes in gathered.drives:
        owner._bind_drive(server, nodes)


async def add_lines(owner: OpcuaServer, server: Server, lines: Sequence[ServedLine]) -> None:
    """*lines* served from now on (a reload added them)."""
    assert owner._lines_folder is not None
    space = SpaceBuilder(owner.namespace)
    gathered = gather_lines(owner, space, owner._lines_folder, lines)
    await space.commit(server.nodes.objects.session)
    finish_lines(owner, server, gathered)


async def _tell_watchers(owner: OpcuaServer, server: Server, doomed: Sequence[ua.NodeId]) -> None:
    """Each monitored item on a node about to go gets Bad_NodeIdUnknown as its last value
    (Part 4, 7.19), then lets go of the node.

    asyncua would call each item's callback on deleting the node, but calls the
    coroutine without awaiting it (a warning, and nothing sent): the items are
    told by a write first, and their callbacks removed, so the deletion finds none.
    """
    aspace = server.iserver.aspace
    gone = ServedDataValue(
        Value=ua.Variant(None, ua.VariantType.Null),
        StatusCode=ua.StatusCode(ua.StatusCodes.BadNodeIdUnknown),
        ServerTimestamp=datetime.now(UTC),
    )
    for node_id in doomed:
        data = aspace.get(node_id)
        value = None if data is None else data.attributes.get(ua.AttributeIds.Value)
        if value is None or not value.datachange_callbacks:
            continue
        if not push_frozen(server, node_id, gone):
            await server.write_attribute_value(node_id, gone)
        for handle in list(value.datachange_callbacks):
            aspace.delete_datachange_callback(handle)


async def remove_line(owner: OpcuaServer, server: Server, name: str) -> None:
    """Line *name* served no more (a reload removed it): see the module docstring."""
    for key in [key for key in owner._drives if key[0] == name]:
        owner._unbind_drive(owner._drives.pop(key))
    owner._lines[:] = [n for n in owner._lines if n.line.config.name != name]
    table: LazyNodes | None = owner._table
    if table is not None:
        table.forget_line(name)
    aspace = server.iserver.aspace
    prefix = f"{name}/"
    doomed = [
        node_id
        for node_id in list(aspace.keys())
        if node_id.NamespaceIndex == owner.namespace
        and isinstance(node_id.Identifier, str)
        and (node_id.Identifier == name or node_id.Identifier.startswith(prefix))
    ]
    owner._counters.forget(doomed)
    await _tell_watchers(owner, server, doomed)
    # Not each deleted node's references looked for in every node (asyncua's
    # DeleteTargetReferences): the one pointing in from outside the line is the folder's.
    await delete_nodes(
        server.iserver.isession,
        [server.get_node(node_id) for node_id in doomed],
        delete_target_references=False,
    )
    if owner._lines_folder is not None:
        folder = aspace.get(owner._lines_folder)
        if folder is not None:
            line_id = ua.NodeId(name, owner.namespace)
            folder.references[:] = [r for r in folder.references if r.NodeId != line_id]
