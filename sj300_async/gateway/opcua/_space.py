"""Building the address space: nodes gathered first, then added in one call.

asyncua's convenience calls (``add_variable``, ``add_property``) add one
node per request through the server's own session, reading the parent's
type each time; a gateway of 64 drives has thousands of nodes. The
:class:`SpaceBuilder` gathers every node as an ``AddNodesItem`` and adds
them all in one ``add_nodes`` call, with the type definitions OPC 40400
uses (``AnalogUnitType`` with its ``EngineeringUnits``, ``EURange``,
``MultiStateDiscreteType`` with ``EnumStrings``).

Node ids are strings in the gateway's namespace, made of the browse path
(``line1/Drive3/Monitoring/ConverterOutputFrequency``): stable across
restarts, so a SCADA's tag configuration survives them.

Engineering units are UNECE Recommendation 20 common codes, encoded as
OPC UA Part 8 (5.6.3) says: the code's characters, right-aligned in the
UnitId integer.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Final

from asyncua import ua

__all__ = ["UNECE", "Argument", "SpaceBuilder", "eu_information"]

_UNITS_NAMESPACE: Final = "http://www.opcfoundation.org/UA/units/un/cefact"
#: The catalogue's units as UNECE common codes, with the unit's name.
UNECE: Final = {
    "Hz": ("HTZ", "hertz"),
    "kHz": ("KHZ", "kilohertz"),
    "A": ("AMP", "ampere"),
    "V": ("VLT", "volt"),
    "kW": ("KWT", "kilowatt"),
    "%": ("P1", "percent"),
    "s": ("SEC", "second"),
    "ms": ("C26", "millisecond"),
    "h": ("HUR", "hour"),
    "min": ("MIN", "minute"),
    "ohm": ("OHM", "ohm"),
    "mH": ("C14", "millihenry"),
}
_ANALOG_UNIT_TYPE: Final = ua.NodeId(17497)  # AnalogUnitType
_MULTISTATE_TYPE: Final = ua.NodeId(ua.ObjectIds.MultiStateDiscreteType)
_READ: Final = ua.AccessLevel.CurrentRead.mask
_READ_WRITE: Final = ua.AccessLevel.CurrentRead.mask | ua.AccessLevel.CurrentWrite.mask


def eu_information(unit: str) -> ua.EUInformation | None:
    """The ``EngineeringUnits`` of *unit* (None: no UNECE code known, or no unit)."""
    known = UNECE.get(unit)
    if known is None:
        return None
    code, name = known
    unit_id = 0
    for char in code:
        unit_id = (unit_id << 8) | ord(char)
    return ua.EUInformation(
        NamespaceUri=_UNITS_NAMESPACE,
        UnitId=unit_id,
        DisplayName=ua.LocalizedText(unit),
        Description=ua.LocalizedText(name),
    )


@dataclass(frozen=True, slots=True)
class Argument:
    """A method's input or output argument."""

    name: str
    vtype: ua.VariantType
    description: str


class SpaceBuilder:
    """Gathers nodes, then adds them in one call (see the module docstring)."""

    def __init__(self, namespace: int, *, gather: bool = True) -> None:
        self.namespace = namespace
        #: False: only node ids are made, nothing is gathered (a drive whose nodes the
        #: lazy address space makes from another's: :mod:`._lazy`).
        self.gather = gather
        self._items: list[ua.AddNodesItem] = []

    @property
    def items(self) -> list[ua.AddNodesItem]:
        """The nodes gathered so far, in the order they are added."""
        return self._items

    def node_id(self, path: str) -> ua.NodeId:
        return ua.NodeId(path, self.namespace)

    def _add(
        self,
        node_class: ua.NodeClass,
        parent: ua.NodeId,
        path: str,
        name: str,
        reference: int,
        type_definition: ua.NodeId | None,
        attributes: Any,
        description: str,
    ) -> ua.NodeId:
        node = self.node_id(path)
        attributes.DisplayName = ua.LocalizedText(name)
        attributes.Description = ua.LocalizedText(description or name)
        item = ua.AddNodesItem()
        item.RequestedNewNodeId = node
        item.BrowseName = ua.QualifiedName(name, self.namespace)
        item.NodeClass = node_class
        item.ParentNodeId = parent
        item.ReferenceTypeId = ua.NodeId(reference)
        if type_definition is not None:
            item.TypeDefinition = type_definition
        item.NodeAttributes = attributes
        self._items.append(item)
        return node

    def object(
        self,
        parent: ua.NodeId,
        path: str,
        name: str,
        description: str = "",
        *,
        folder: bool = False,
        component: bool = False,
    ) -> ua.NodeId:
        """An object (a folder when *folder*): a component of *parent* when *component*,
        else organised by it (*parent* is a folder)."""
        if not self.gather:
            return self.node_id(path)
        kind = ua.ObjectIds.FolderType if folder else ua.ObjectIds.BaseObjectType
        reference = ua.ObjectIds.HasComponent if component else ua.ObjectIds.Organizes
        return self._add(
            ua.NodeClass.Object, parent, path, name, reference, ua.NodeId(kind),
            ua.ObjectAttributes(EventNotifier=0), description,
        )  # fmt: skip

    def variable(
        self,
        parent: ua.NodeId,
        path: str,
        name: str,
        vtype: ua.VariantType,
        *,
        description: str = "",
        unit: str = "",
        value_range: tuple[float, float] | None = None,
        states: Sequence[str] = (),
        writable: bool = False,
        array: bool = False,
    ) -> ua.NodeId:
        """A data variable; with a UNECE unit an AnalogUnitType with its EngineeringUnits.

        *array*: its value is a one-dimensional array of *vtype*, of any length.
        """
        if not self.gather:
            return self.node_id(path)
        eu = eu_information(unit)
        type_definition = ua.NodeId(ua.ObjectIds.BaseDataVariableType)
        if eu is not None:
            type_definition = _ANALOG_UNIT_TYPE
        elif states:
            type_definition = _MULTISTATE_TYPE
        access = _READ_WRITE if writable else _READ
        attributes = ua.VariableAttributes(
            Value=ua.Variant(None, ua.VariantType.Null),
            DataType=ua.NodeId(vtype.value),
            ValueRank=ua.ValueRank.OneDimension if array else ua.ValueRank.Scalar,
            ArrayDimensions=[0] if array else None,
            AccessLevel=access,
            UserAccessLevel=access,
            Historizing=False,
            MinimumSamplingInterval=0.0,
        )
        node = self._add(
            ua.NodeClass.Variable, parent, path, name, ua.ObjectIds.HasComponent,
            type_definition, attributes, description,
        )  # fmt: skip
        if eu is not None:
            self.property(node, f"{path}/EngineeringUnits", "EngineeringUnits", eu, 887, ns0=True)
        if value_range is not None:
            low, high = value_range
            self.property(node, f"{path}/EURange", "EURange", ua.Range(low, high), 884, ns0=True)
        if states:
            texts = [ua.LocalizedText(text) for text in states]
            self.property(node, f"{path}/EnumStrings", "EnumStrings", texts, 21, ns0=True)
        return node

    def property(
        self,
        parent: ua.NodeId,
        path: str,
        name: str,
        value: Any,
        datatype: int | ua.VariantType,
        *,
        ns0: bool = False,
    ) -> ua.NodeId:
        """A property (its browse name in namespace 0 when *ns0*: the standard's own)."""
        if not self.gather:
            return self.node_id(path)
        if isinstance(datatype, ua.VariantType):
            variant = ua.Variant(value, datatype)
            datatype_id = ua.NodeId(datatype.value)
        else:
            variant = ua.Variant(value)
            datatype_id = ua.NodeId(datatype)
        array = isinstance(value, list)
        attributes = ua.VariableAttributes(
            Value=variant,
            DataType=datatype_id,
            ValueRank=ua.ValueRank.OneDimension if array else ua.ValueRank.Scalar,
            ArrayDimensions=[len(value)] if array else None,
            AccessLevel=_READ,
            UserAccessLevel=_READ,
        )
        node = self._add(
            ua.NodeClass.Variable, parent, path, name, ua.ObjectIds.HasProperty,
            ua.NodeId(ua.ObjectIds.PropertyType), attributes, "",
        )  # fmt: skip
        if ns0:
            self._items[-1].BrowseName = ua.QualifiedName(name, 0)
        return node

    def method(
        self,
        parent: ua.NodeId,
        path: str,
        name: str,
        description: str,
        inputs: Sequence[Argument] = (),
        outputs: Sequence[Argument] = (),
    ) -> ua.NodeId:
        if not self.gather:
            return self.node_id(path)
        attributes = ua.MethodAttributes(Executable=True, UserExecutable=True)
        node = self._add(
            ua.NodeClass.Method, parent, path, name, ua.ObjectIds.HasComponent,
            None, attributes, description,
        )  # fmt: skip
        for key, arguments in (("InputArguments", inputs), ("OutputArguments", outputs)):
            if arguments:
                values = [
                    ua.Argument(
                        Name=argument.name,
                        DataType=ua.NodeId(argument.vtype.value),
                        ValueRank=ua.ValueRank.Scalar,
                        ArrayDimensions=[],
                        Description=ua.LocalizedText(argument.description),
                    )
                    for argument in arguments
                ]
                self.property(node, f"{path}/{key}", key, values, ua.ObjectIds.Argument, ns0=True)
        return node

    async def commit(self, session: Any) -> None:
        """Add every gathered node (raises on the first the server refuses)."""
        items, self._items = self._items, []
        results = await session.add_nodes(items)
        for item, result in zip(items, results, strict=True):
            if not result.StatusCode.is_good():
                raise RuntimeError(
                    f"cannot add node {item.RequestedNewNodeId}: {result.StatusCode}"
                )
