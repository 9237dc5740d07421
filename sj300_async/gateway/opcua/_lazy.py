"""A drive's nodes made when a client asks for them: the address space without a copy per drive.

Why: asyncua keeps a node as a ``NodeData`` holding, per attribute, an
``AttributeValue``, a ``DataValue`` and a ``Variant``, and per reference a
``ReferenceDescription``: a drive's 38 nodes cost more memory than the rest
of the gateway's share of that drive together (issue 44; the figures are
in the CHANGELOG). A SCADA reads or watches a few of them.

How:

- **Shapes.** Drives whose nodes differ only by their
  :class:`~._model.DriveIdentity` share a shape (:func:`~._model.shape_key`).
  Per shape, one drive's nodes are made once, at start, by asyncua's own
  node management (its add-node path, into a scratch space over the real
  one): the shape's prototypes.
- **The node table.** asyncua's ``AddressSpace`` keeps its nodes in a
  mapping (``_nodes``); asyncua itself puts a mapping of its own there when
  it loads a shelf (``LazyNodes`` does what its ``LazyLoadingDict`` does).
  :class:`LazyNodes` holds every node asyncua made (namespace 0, the
  ``Lines`` folder, each line and its counters) and makes a drive's node
  from its shape's prototype when asyncua looks it up: the node id, the
  drive's identity and the references into the drive rewritten, every
  other attribute value shared with the prototype. Sharing is safe
  because asyncua replaces an attribute's value when it writes one and
  never changes one in place, and the gateway refuses every write but a
  parameter's, which goes to the drive (:mod:`._hooks`), not the node.
- **The server binds it** (a value's read callback, a method's handler)
  as it makes it: :attr:`LazyNodes.bind`.
- **Bounded.** Nodes made are kept while a monitored item is on one of
  their attributes (asyncua finds the item's node by id when it deletes
  it), and otherwise the :data:`KEEP_NODES` made last: a client browsing
  the whole plant costs a bounded amount of memory, and time per node.
- Each line object's reference to each of its drives is made at start: a
  browse of a line lists its drives without making them.

This reaches past asyncua's public API (its node table, ``NodeData``, and
its node management's ``_add_node``), so it is one of the speed patches
(:mod:`._speedups`): where those are off, the server adds every node
through asyncua's public ``add_nodes``, as before.
``tests/opcua/test_opcua_lazy.py`` compares every node made here with the
one asyncua makes for the same drive.
"""

from __future__ import annotations

import collections
import copy
import dataclasses
from collections.abc import Callable, Iterator, MutableMapping, Sequence
from dataclasses import dataclass
from typing import Any, Final

from asyncua import ua
from asyncua.crypto.permission_rules import User, UserRole
from asyncua.server.address_space import (
    AddressSpace,
    AttributeValue,
    NodeData,
    NodeManagementService,
)

from ._model import DriveIdentity

__all__ = ["KEEP_NODES", "LazyNodes", "Shape", "make_shape"]

#: Drive nodes made and watched by no monitored item that are kept (the oldest go first).
#: A node costs some 6 KiB: at most about 24 MiB, however much a client browses.
KEEP_NODES: Final = 4096
_ADMIN: Final = User(role=UserRole.Admin)
#: The attributes a drive object's identity sets.
_OBJECT_NAMES: Final = (
    ua.AttributeIds.BrowseName,
    ua.AttributeIds.DisplayName,
    ua.AttributeIds.Description,
)


@dataclass(frozen=True, slots=True)
class Shape:
    """One drive's nodes as asyncua made them, by path below the drive object."""

    #: The prototype drive object's path (``line1/Drive3``) and node id's namespace.
    path: str
    namespace: int
    #: Its line object (the drive object's inverse reference names it).
    line: ua.NodeId
    #: Path below the drive object ("" for the drive object itself) -> its prototype.
    nodes: dict[str, NodeData]
    #: The line object's reference to the prototype drive object.
    forward: ua.ReferenceDescription


def make_shape(
    space: AddressSpace, items: Sequence[ua.AddNodesItem], path: str, line: ua.NodeId
) -> Shape:
    """The prototypes of *items* (a drive's nodes, its object first, at *path* under the
    *line* object), made by asyncua's own node management without touching *space*."""
    real = space._nodes
    if isinstance(real, LazyNodes):  # not the drive nodes it would make: only asyncua's
        real = real._nodes
    line_data = real[line]
    # The line as the prototype's parent, with references of its own: asyncua adds the
    # drive object's reference to the parent it is given.
    stand_in = NodeData(line)
    stand_in.attributes = line_data.attributes
    made: dict[ua.NodeId, NodeData] = {line: stand_in}
    scratch = AddressSpace()
    scratch.force_server_timestamp = space.force_server_timestamp
    scratch._nodes = collections.ChainMap(made, real)
    service = NodeManagementService(scratch)
    for item in items:
        result = service._add_node(item, _ADMIN)
        if not result.StatusCode.is_good():
            raise RuntimeError(f"cannot add node {item.RequestedNewNodeId}: {result.StatusCode}")
    del made[line]
    nodes = {
        str(node_id.Identifier).removeprefix(path).removeprefix("/"): data
        for node_id, data in made.items()
    }
    (forward,) = stand_in.references
    return Shape(path, items[0].RequestedNewNodeId.NamespaceIndex, line, nodes, forward)


@dataclass(frozen=True, slots=True)
class _Drive:
    """What a drive's nodes are made of."""

    shape: Shape
    #: Its own names and properties (computed when a node is made: kept small per drive).
    identity: Callable[[], DriveIdentity]
    line: ua.NodeId


def _rename(value: AttributeValue, new: object, vtype: ua.VariantType) -> AttributeValue:
    assert value.value is not None
    data = copy.copy(value.value)  # dataclasses.replace runs __init__: 5x slower
    data.Value = ua.Variant(new, vtype)
    return AttributeValue(data)


def _moved(ref: ua.ReferenceDescription, **fields: object) -> ua.ReferenceDescription:
    """*ref* with *fields* changed (a copy: the prototype's stays as it is)."""
    moved = copy.copy(ref)
    for name, value in fields.items():
        setattr(moved, name, value)
    return moved


class _Maker:
    """Makes one drive's node from its prototype."""

    def __init__(self, real: dict[ua.NodeId, NodeData], drive: _Drive) -> None:
        self.shape = shape = drive.shape
        self.identity = drive.identity()
        self.path = self.identity.path
        self.object = ua.NodeId(self.path, shape.namespace)
        line = real[drive.line].attributes
        self.line = drive.line
        self.line_names = (
            line[ua.AttributeIds.BrowseName].value.Value.Value,
            line[ua.AttributeIds.DisplayName].value.Value.Value,
        )

    def make(self, node_id: ua.NodeId, relative: str, prototype: NodeData) -> NodeData:
        node = NodeData(node_id)
        attributes = node.attributes
        for attribute, value in prototype.attributes.items():
            attributes[attribute] = AttributeValue(value.value)  # shared: see the docstring
        attributes[ua.AttributeIds.NodeId] = _rename(
            prototype.attributes[ua.AttributeIds.NodeId], node_id, ua.VariantType.NodeId
        )
        identity = self.identity
        if not relative:
            names = (
                ua.QualifiedName(identity.name, self.shape.namespace),
                ua.LocalizedText(identity.name),
                ua.LocalizedText(identity.description),
            )
            for attribute, name in zip(_OBJECT_NAMES, names, strict=True):
                vtype = prototype.attributes[attribute].value.Value.VariantType
                attributes[attribute] = _rename(prototype.attributes[attribute], name, vtype)
        else:
            for name, value, vtype in identity.properties:
                if relative == name:
                    attributes[ua.AttributeIds.Value] = _rename(
                        prototype.attributes[ua.AttributeIds.Value], value, vtype
                    )
        node.references = [self._reference(ref) for ref in prototype.references]
        return node

    def _reference(self, ref: ua.ReferenceDescription) -> ua.ReferenceDescription:
        target = ref.NodeId
        shape = self.shape
        if target == shape.line:  # the drive object's, to its line
            browse, display = self.line_names
            return _moved(ref, NodeId=self.line, BrowseName=browse, DisplayName=display)
        identifier = target.Identifier
        if target.NamespaceIndex != shape.namespace or not isinstance(identifier, str):
            return ref  # to namespace 0 (a type definition): shared
        if identifier == shape.path:  # to the drive object
            return _moved(
                ref,
                NodeId=self.object,
                BrowseName=ua.QualifiedName(self.identity.name, shape.namespace),
                DisplayName=ua.LocalizedText(self.identity.name),
            )
        if identifier.startswith(f"{shape.path}/"):  # to another of the drive's nodes
            moved = ua.NodeId(self.path + identifier[len(shape.path) :], shape.namespace)
            return _moved(ref, NodeId=moved)
        return ref


def _watched(node: NodeData) -> bool:
    """A monitored item is on one of *node*'s attributes."""
    return any(value.datachange_callbacks for value in node.attributes.values())


class LazyNodes(MutableMapping[ua.NodeId, NodeData]):
    """asyncua's node table, making a drive's nodes as asyncua looks them up (see the
    module docstring)."""

    def __init__(
        self,
        nodes: dict[ua.NodeId, NodeData],
        namespace: int,
        bind: Callable[[ua.NodeId, NodeData], None],
        keep: int = KEEP_NODES,
    ) -> None:
        #: Every node asyncua made, and the drive nodes made and kept now.
        self._nodes = nodes
        self._namespace = namespace
        #: The server's: binds a node made (its value's read callback, a method's handler).
        self.bind = bind
        self.keep = keep
        #: (line name, "Drive<node>") -> the drive.
        self._drives: dict[tuple[str, str], _Drive] = {}
        #: Drive nodes made and unwatched when last looked at, the oldest first.
        self._made: dict[ua.NodeId, None] = {}
        #: Drive nodes made that a monitored item watched when last looked at.
        self._kept: dict[ua.NodeId, None] = {}
        #: Nodes made, and dropped again, since start.
        self.made = 0
        self.dropped = 0

    @classmethod
    def install(
        cls,
        space: AddressSpace,
        namespace: int,
        bind: Callable[[ua.NodeId, NodeData], None],
        keep: int = KEEP_NODES,
    ) -> LazyNodes:
        """Put a LazyNodes holding *space*'s nodes in its place."""
        table = cls(space._nodes, namespace, bind, keep)
        space._nodes = table
        return table

    def add_drive(
        self, shape: Shape, identity: Callable[[], DriveIdentity], line: ua.NodeId
    ) -> None:
        """A drive of *shape* under the *line* object: its object is listed there now, its
        nodes are made when looked up."""
        made = identity()
        line_name, _, drive_name = made.path.partition("/")
        self._drives[(line_name, drive_name)] = _Drive(shape, identity, line)
        self._nodes[line].references.append(
            dataclasses.replace(
                shape.forward,
                NodeId=ua.NodeId(made.path, self._namespace),
                BrowseName=ua.QualifiedName(made.name, self._namespace),
                DisplayName=ua.LocalizedText(made.name),
            )
        )

    def forget_line(self, line: str) -> None:
        """Line *line*'s drives are made no more (a reload removed it: ._relines); the
        nodes made so far stay until deleted."""
        for key in [key for key in self._drives if key[0] == line]:
            del self._drives[key]

    def served(self) -> int:
        """Nodes in the namespace, made or not."""
        eager = sum(
            1
            for node in self._nodes
            if node.NamespaceIndex == self._namespace and node not in self._made
            and node not in self._kept
        )  # fmt: skip
        return eager + sum(len(drive.shape.nodes) for drive in self._drives.values())

    @property
    def kept(self) -> int:
        """Drive nodes made and held now."""
        return len(self._made) + len(self._kept)

    # -- the mapping asyncua uses ----------------------------------------------------

    def get(self, key: ua.NodeId, default: Any = None) -> Any:
        node = self._nodes.get(key)
        if node is None:
            node = self._make(key)
            if node is None:
                return default
        return node

    def __getitem__(self, key: ua.NodeId) -> NodeData:
        node = self.get(key)
        if node is None:
            raise KeyError(key)
        return node

    def __contains__(self, key: object) -> bool:
        return isinstance(key, ua.NodeId) and self.get(key) is not None

    def __setitem__(self, key: ua.NodeId, value: NodeData) -> None:
        self._nodes[key] = value

    def __delitem__(self, key: ua.NodeId) -> None:
        del self._nodes[key]
        self._made.pop(key, None)
        self._kept.pop(key, None)

    def __iter__(self) -> Iterator[ua.NodeId]:
        return iter(self._nodes)

    def __len__(self) -> int:
        return len(self._nodes)

    # -- making and dropping ---------------------------------------------------------

    def _make(self, key: ua.NodeId) -> NodeData | None:
        identifier = key.Identifier
        if key.NamespaceIndex != self._namespace or not isinstance(identifier, str):
            return None
        line, _, rest = identifier.partition("/")
        drive_name, slash, relative = rest.partition("/")
        if slash and not relative:  # "line1/Drive3/" is no node
            return None
        drive = self._drives.get((line, drive_name))
        if drive is None:
            return None
        prototype = drive.shape.nodes.get(relative)
        if prototype is None:
            return None
        node = _Maker(self._nodes, drive).make(key, relative, prototype)
        self.bind(key, node)
        self._nodes[key] = node
        self._made[key] = None
        self.made += 1
        self._trim()
        return node

    def _trim(self) -> None:
        """Drop the oldest unwatched nodes made past :attr:`keep`; look at two watched ones."""
        made, kept = self._made, self._kept
        while len(made) > self.keep:
            oldest = next(iter(made))
            del made[oldest]
            node = self._nodes.get(oldest)
            if node is not None and _watched(node):
                kept[oldest] = None  # asyncua deletes its monitored items by node id
            elif node is not None:
                del self._nodes[oldest]
                self.dropped += 1
        for _ in range(min(2, len(kept))):  # watched once: back among the droppable when not
            first = next(iter(kept))
            del kept[first]
            node = self._nodes.get(first)
            if node is None:
                continue
            if _watched(node):
                kept[first] = None
            else:
                made[first] = None
