"""Sparkplug B's payload schema, built at import from its field table (no generated code).

The schema is the specification's ``sparkplug_b.proto`` (Sparkplug 3.0,
section 6.4.1: package ``org.eclipse.tahu.protobuf``, proto2), written here
as data: each message's fields by number, label, type and ``oneof``. The
protobuf runtime (upb) builds the message classes from it, so there is no
``protoc`` step and no generated module to keep in step with the runtime's
version. What the edge node never sends (data sets, templates) is in the
schema all the same, so a command carrying one decodes, and is refused as
the wrong type rather than misread. Extension ranges are left out: their
fields decode as unknown fields, which the edge node ignores.

The classes are untyped for mypy (the runtime makes them); :mod:`._payload`
is the typed face the rest of the package uses.
"""

from __future__ import annotations

from typing import Any, Final

from google.protobuf import descriptor_pb2, descriptor_pool, message_factory

__all__ = ["DATA_TYPES", "PACKAGE", "Payload"]

PACKAGE: Final = "org.eclipse.tahu.protobuf"

#: Sparkplug B's data types (the DataType enum), by name.
DATA_TYPES: Final = {
    name: number
    for number, name in enumerate(
        (
            *("Unknown", "Int8", "Int16", "Int32", "Int64", "UInt8", "UInt16", "UInt32"),
            *("UInt64", "Float", "Double", "Boolean", "String", "DateTime", "Text", "UUID"),
            *("DataSet", "Bytes", "File", "Template", "PropertySet", "PropertySetList"),
            *("Int8Array", "Int16Array", "Int32Array", "Int64Array", "UInt8Array"),
            *("UInt16Array", "UInt32Array", "UInt64Array", "FloatArray", "DoubleArray"),
            *("BooleanArray", "StringArray", "DateTimeArray"),
        )
    )
}

_F = descriptor_pb2.FieldDescriptorProto
_SCALARS: Final = {
    "uint32": _F.TYPE_UINT32,
    "uint64": _F.TYPE_UINT64,
    "float": _F.TYPE_FLOAT,
    "double": _F.TYPE_DOUBLE,
    "bool": _F.TYPE_BOOL,
    "string": _F.TYPE_STRING,
    "bytes": _F.TYPE_BYTES,
}

#: (number, name, type, repeated, oneof): a type not in _SCALARS is a message of Payload's.
Field = tuple[int, str, str, bool, str | None]

#: The oneof ``value`` of a property value, a metric, a template parameter and a data
#: set value share their scalar members; each message numbers them from its own start.
_VALUE_SCALARS: Final = (
    ("int_value", "uint32"),
    ("long_value", "uint64"),
    ("float_value", "float"),
    ("double_value", "double"),
    ("boolean_value", "bool"),
    ("string_value", "string"),
)


def _values(first: int, *more: tuple[str, str]) -> tuple[Field, ...]:
    members = (*_VALUE_SCALARS, *more)
    return tuple((first + i, name, kind, False, "value") for i, (name, kind) in enumerate(members))


#: Payload's nested messages, each after its parent, and Payload itself ("").
_MESSAGES: Final[dict[str, tuple[Field, ...]]] = {
    "Template": (
        (1, "version", "string", False, None),
        (2, "metrics", "Metric", True, None),
        (3, "parameters", "Template.Parameter", True, None),
        (4, "template_ref", "string", False, None),
        (5, "is_definition", "bool", False, None),
    ),
    "Template.Parameter": (
        (1, "name", "string", False, None),
        (2, "type", "uint32", False, None),
        *_values(3, ("extension_value", "Template.Parameter.ParameterValueExtension")),
    ),
    "Template.Parameter.ParameterValueExtension": (),
    "DataSet": (
        (1, "num_of_columns", "uint64", False, None),
        (2, "columns", "string", True, None),
        (3, "types", "uint32", True, None),
        (4, "rows", "DataSet.Row", True, None),
    ),
    "DataSet.DataSetValue": _values(
        1, ("extension_value", "DataSet.DataSetValue.DataSetValueExtension")
    ),
    "DataSet.DataSetValue.DataSetValueExtension": (),
    "DataSet.Row": ((1, "elements", "DataSet.DataSetValue", True, None),),
    "PropertyValue": (
        (1, "type", "uint32", False, None),
        (2, "is_null", "bool", False, None),
        *_values(
            3,
            ("propertyset_value", "PropertySet"),
            ("propertysets_value", "PropertySetList"),
            ("extension_value", "PropertyValue.PropertyValueExtension"),
        ),
    ),
    "PropertyValue.PropertyValueExtension": (),
    "PropertySet": (
        (1, "keys", "string", True, None),
        (2, "values", "PropertyValue", True, None),
    ),
    "PropertySetList": ((1, "propertyset", "PropertySet", True, None),),
    "MetaData": (
        (1, "is_multi_part", "bool", False, None),
        (2, "content_type", "string", False, None),
        (3, "size", "uint64", False, None),
        (4, "seq", "uint64", False, None),
        (5, "file_name", "string", False, None),
        (6, "file_type", "string", False, None),
        (7, "md5", "string", False, None),
        (8, "description", "string", False, None),
    ),
    "Metric": (
        (1, "name", "string", False, None),
        (2, "alias", "uint64", False, None),
        (3, "timestamp", "uint64", False, None),
        (4, "datatype", "uint32", False, None),
        (5, "is_historical", "bool", False, None),
        (6, "is_transient", "bool", False, None),
        (7, "is_null", "bool", False, None),
        (8, "metadata", "MetaData", False, None),
        (9, "properties", "PropertySet", False, None),
        # The metric's oneof numbers bytes before the data set and the template.
        *_values(
            10,
            ("bytes_value", "bytes"),
            ("dataset_value", "DataSet"),
            ("template_value", "Template"),
            ("extension_value", "Metric.MetricValueExtension"),
        ),
    ),
    "Metric.MetricValueExtension": (),
    "": (
        (1, "timestamp", "uint64", False, None),
        (2, "metrics", "Metric", True, None),
        (3, "seq", "uint64", False, None),
        (4, "uuid", "string", False, None),
        (5, "body", "bytes", False, None),
    ),
}


def _message(name: str, fields: tuple[Field, ...]) -> descriptor_pb2.DescriptorProto:
    message = descriptor_pb2.DescriptorProto(name=name.rsplit(".", 1)[-1])
    oneofs: list[str] = []
    for number, field_name, kind, repeated, oneof in fields:
        field = message.field.add(
            name=field_name,
            number=number,
            label=_F.LABEL_REPEATED if repeated else _F.LABEL_OPTIONAL,
        )
        if kind in _SCALARS:
            field.type = _SCALARS[kind]
        else:
            field.type = _F.TYPE_MESSAGE
            field.type_name = f".{PACKAGE}.Payload.{kind}"
        if oneof is not None:
            if oneof not in oneofs:
                oneofs.append(oneof)
                message.oneof_decl.add(name=oneof)
            field.oneof_index = oneofs.index(oneof)
    return message


def _build() -> Any:
    file = descriptor_pb2.FileDescriptorProto(
        name="sj300_async/sparkplug_b.proto", package=PACKAGE, syntax="proto2"
    )
    payload = _message("Payload", _MESSAGES[""])
    made: dict[str, descriptor_pb2.DescriptorProto] = {"": payload}
    for name, fields in _MESSAGES.items():  # parents come before their nested messages
        if name:
            parent = made[name.rsplit(".", 1)[0] if "." in name else ""]
            made[name] = parent.nested_type.add()
            made[name].CopyFrom(_message(name, fields))
    file.message_type.append(payload)
    data_type = file.enum_type.add(name="DataType")
    for name, number in DATA_TYPES.items():
        data_type.value.add(name=name, number=number)
    pool = descriptor_pool.DescriptorPool()
    pool.Add(file)
    return message_factory.GetMessageClass(pool.FindMessageTypeByName(f"{PACKAGE}.Payload"))


#: The Payload message class (``Payload()``, ``Payload.FromString(data)``).
Payload: Any = _build()
