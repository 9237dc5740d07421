"""gateway/opcua/_wire.py packs a DataValue as asyncua's own encoder does, byte for byte.

The oracle is asyncua's generic encoder (the factory as it was before
encode_frozen_values). Every shape the gateway serves must be packed here
(not left to asyncua); every other shape must be left to it (None).
"""

from __future__ import annotations

from datetime import UTC, datetime, timedelta
from typing import Any

from asyncua import ua
from asyncua.ua import ua_binary
from hypothesis import given
from hypothesis import strategies as st

from sj300_async.gateway.opcua import _speedups
from sj300_async.gateway.opcua._wire import datavalue_binary

_generic = (_speedups._serializers or ua_binary.create_dataclass_serializer)(ua.DataValue)

_RANGES: dict[ua.VariantType, st.SearchStrategy[Any]] = {
    ua.VariantType.Boolean: st.booleans(),
    ua.VariantType.SByte: st.integers(-(2**7), 2**7 - 1),
    ua.VariantType.Byte: st.integers(0, 2**8 - 1),
    ua.VariantType.Int16: st.integers(-(2**15), 2**15 - 1),
    ua.VariantType.UInt16: st.integers(0, 2**16 - 1),
    ua.VariantType.Int32: st.integers(-(2**31), 2**31 - 1),
    ua.VariantType.UInt32: st.integers(0, 2**32 - 1),
    ua.VariantType.Int64: st.integers(-(2**63), 2**63 - 1),
    ua.VariantType.UInt64: st.integers(0, 2**64 - 1),
    ua.VariantType.Float: st.floats(width=32),
    ua.VariantType.Double: st.floats(),
}
# From before 1601 (encoded as 0) to past 9999 (the largest Int64), and the present.
_TIMES = st.datetimes(
    min_value=datetime(1500, 1, 1), max_value=datetime(9999, 12, 31, 23, 59, 59)
).map(lambda t: t.replace(tzinfo=UTC)) | st.just(datetime.now(UTC))
_STATUS = st.sampled_from(
    [0, ua.StatusCodes.UncertainLastUsableValue, ua.StatusCodes.BadWaitingForInitialData]
)


@st.composite
def _scalar(draw: st.DrawFn) -> ua.Variant:
    vtype = draw(st.sampled_from(sorted(_RANGES, key=int)))
    return ua.Variant(draw(_RANGES[vtype]), vtype)


def _frozen(variant: ua.Variant, status: int, source: datetime, server: datetime) -> Any:
    return _speedups.FrozenDataValue(
        Value=variant,
        StatusCode=ua.StatusCode(status),
        SourceTimestamp=source,
        ServerTimestamp=server,
    )


@given(_scalar(), _STATUS, _TIMES, _TIMES)
def test_a_scalar_is_packed_as_asyncua_packs_it(
    variant: ua.Variant, status: int, source: datetime, server: datetime
) -> None:
    value = _frozen(variant, status, source, server)
    assert datavalue_binary(value) == _generic(value)


@given(_STATUS, _TIMES, _TIMES)
def test_no_value_is_packed_as_asyncua_packs_it(
    status: int, source: datetime, server: datetime
) -> None:
    value = _frozen(ua.Variant(None, ua.VariantType.Null), status, source, server)
    assert datavalue_binary(value) == _generic(value)


@given(
    st.sampled_from(
        [
            ua.Variant("M1", ua.VariantType.String),
            ua.Variant([1.0, 2.0], ua.VariantType.Double),
            ua.Variant(ua.LocalizedText("x"), ua.VariantType.LocalizedText),
        ]
    ),
    _TIMES,
)
def test_other_shapes_are_left_to_asyncua(variant: ua.Variant, at: datetime) -> None:
    assert datavalue_binary(_frozen(variant, 0, at, at)) is None


def test_picoseconds_a_missing_timestamp_and_an_unpackable_value_are_left_to_asyncua() -> None:
    now = datetime.now(UTC)
    double = ua.Variant(1.5, ua.VariantType.Double)
    with_picoseconds = _frozen(double, 0, now, now)
    with_picoseconds.SourcePicoseconds = 10
    assert datavalue_binary(with_picoseconds) is None
    assert datavalue_binary(_speedups.FrozenDataValue(Value=double, SourceTimestamp=now)) is None
    too_large = _frozen(ua.Variant(2**40, ua.VariantType.Int32), 0, now, now)
    assert datavalue_binary(too_large) is None
    assert datavalue_binary(_frozen(double, 0, now, now + timedelta(seconds=1))) == _generic(
        _frozen(double, 0, now, now + timedelta(seconds=1))
    )
