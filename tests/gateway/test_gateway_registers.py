"""The register map, sans-IO: encodings, staleness, and what a write asks for."""

from __future__ import annotations

import math

import pytest

from sj300_async.bus import register_protocol, unregister_protocol
from sj300_async.gateway import (
    GatewayDrive,
    Heartbeat,
    Lease,
    LineConfig,
    ParameterWrite,
    Refusal,
    RunCommand,
    SetFrequency,
    WriteRequest,
    WriteResult,
)
from sj300_async.gateway.modbus import REFUSAL_CODES, Exc, Field, RegisterMap, parameter_address
from sj300_async.gateway.modbus._registers import (
    _UNTIL,
    MAX_CACHED_READS,
    ReadCache,
    _protocol_field,
)
from sj300_async.profiles import RegisterField, Trip, TripLog, get_profile
from sj300_async.wire import Direction

SJ300, FR700 = get_profile("sj300"), get_profile("fr700")


def refusal(decoded: WriteRequest | WriteResult) -> Refusal | None:
    """The refusal of a decoded write (and a sentence saying why), None for a request."""
    if not isinstance(decoded, WriteResult):
        return None
    assert decoded.detail
    return decoded.refusal


def _state(protocol: str = "sj300") -> GatewayDrive:
    line = LineConfig("l", "sim://", protocol, (1,), unit_offset=0)
    return GatewayDrive(line, 1, get_profile(protocol), Lease(5.0), stale_after_s=5.0)


@pytest.mark.parametrize(
    ("value", "width", "signed", "words"),
    [
        (1234, 1, False, [1234]),
        (70000, 1, False, [65535]),  # saturates, never wraps
        (-5, 1, False, [0]),
        (-5, 1, True, [65531]),  # two's complement
        (-40000, 1, True, [32768]),  # saturates at -32768
        (70000, 2, False, [1, 4464]),  # high word first
        (-2, 2, True, [65535, 65534]),
        (1 << 40, 2, True, [32767, 65535]),
    ],
)
def test_values_are_encoded_high_word_first_and_saturate(
    value: int, width: int, signed: bool, words: list[int]
) -> None:
    field = Field(0, "x", "1", lambda s, now: value, width=width, signed=signed)
    assert field.words(_state().served, 0.0) == words


def test_parameter_addresses_follow_the_group_bases() -> None:
    assert parameter_address(SJ300, "F002") == 10004
    assert parameter_address(SJ300, "A004") == 12008
    assert parameter_address(SJ300, "P049") == 20098
    assert parameter_address(FR700, "Pr.7") == 30014
    assert parameter_address(FR700, "Pr.999") == 31998
    assert parameter_address(SJ300, "Pr.7") is None
    register_protocol("toy", "toyproto:TOY_DIALECT")  # tests/toyproto: no parameter blocks
    try:
        assert parameter_address(get_profile("toy"), "A004") is None
    finally:
        unregister_protocol("toy")


def test_a_read_is_whole_or_refused() -> None:
    regs = RegisterMap(SJ300, ["A004"])
    state = _state()
    now = 100.0
    assert regs.read(state.served, 12008, 2, now) == Exc.TARGET_FAILED  # never read
    state.readings.set_parameter("A004", 500, 99.0)
    state.rebuild(99.0)
    assert regs.read(state.served, 12008, 2, now) == [0, 500]
    assert regs.read(state.served, 12009, 1, now) == [500]  # half of it may be read
    assert regs.read(state.served, 12008, 3, now) == Exc.ILLEGAL_ADDRESS
    assert regs.read(state.served, 12008, 2, 103.9) == [0, 500]
    assert regs.read(state.served, 12008, 2, 104.1) == Exc.TARGET_FAILED  # stale
    # The identity block is never stale.
    assert regs.read(state.served, 0, 4, 1e9) == [0, 65535, 1, 1]


def test_fr700_units_have_no_sj300_registers() -> None:
    regs = RegisterMap(FR700, ["Pr.7"])
    state = _state("fr700")
    assert regs.read(state.served, 104, 1, 0.0) == Exc.ILLEGAL_ADDRESS
    assert regs.read(state.served, 300, 2, 0.0) == Exc.ILLEGAL_ADDRESS
    assert regs.read(state.served, 0, 4, 0.0) == [0, 65535, 2, 1]


def test_what_a_write_asks_for() -> None:
    regs = RegisterMap(SJ300, ["A004"])
    assert regs.decode_write(1000, [7]) == Heartbeat()
    assert regs.decode_write(1002, [2]) == RunCommand(Direction.REVERSE)
    assert refusal(regs.decode_write(1002, [3])) == Refusal.INVALID_VALUE
    assert regs.decode_write(1003, [2550]) == SetFrequency(25.5)
    assert regs.decode_write(12008, [0, 600]) == ParameterWrite("A004", 600)
    assert regs.decode_write(12008, [65535, 65535]) == ParameterWrite("A004", -1)
    assert refusal(regs.decode_write(12009, [600])) == Refusal.MALFORMED  # half a value
    assert refusal(regs.decode_write(1002, [1, 2500])) == Refusal.MALFORMED  # two targets
    assert refusal(regs.decode_write(1001, [1])) == Refusal.NOT_ALLOWED  # read-only
    assert refusal(regs.decode_write(100, [1])) == Refusal.NOT_ALLOWED
    assert refusal(regs.decode_write(999, [1])) == Refusal.UNKNOWN_TARGET
    assert refusal(regs.decode_write(1003, [1, 1])) == Refusal.UNKNOWN_TARGET  # no 1004
    # Each answered with the exception its meaning is closest to, as before.
    assert [REFUSAL_CODES[r] for r in (Refusal.INVALID_VALUE, Refusal.MALFORMED)] == [
        Exc.ILLEGAL_VALUE,
        Exc.ILLEGAL_VALUE,
    ]
    assert REFUSAL_CODES[Refusal.NOT_ALLOWED] == Exc.ILLEGAL_FUNCTION
    assert REFUSAL_CODES[Refusal.UNKNOWN_TARGET] == Exc.ILLEGAL_ADDRESS


def test_the_lease_registers_show_the_lease() -> None:
    regs = RegisterMap(SJ300)
    state = _state()
    state.lease.holder, state.lease.expires_at = "10.0.0.9", 12.5
    assert regs.read(state.served, 1000, 2, 10.0) == [1, 25]
    assert regs.read(state.served, 1000, 2, 13.0) == [0, 0]
    assert math.isinf(_state().lease.expires_at)


def test_a_read_of_the_same_snapshot_is_answered_from_the_cache_while_fresh() -> None:
    regs = RegisterMap(SJ300, ["A004"])
    state = _state()
    cache: ReadCache = {}
    state.readings.set_parameter("A004", 500, 99.0)
    state.rebuild(99.0)
    assert regs.read(state.served, 12008, 2, 100.0, cache) == [0, 500]
    assert cache[12008, 2][0] is state.served  # kept with the served view it came from
    assert regs.read(state.served, 12008, 2, 101.0, cache) == [0, 500]
    # Past its served deadline: refused, not the kept answer.
    assert regs.read(state.served, 12008, 2, 104.1, cache) == Exc.TARGET_FAILED
    # A new snapshot: its values, not the kept ones.
    state.readings.set_parameter("A004", 600, 104.0)
    state.rebuild(104.0)
    assert regs.read(state.served, 12008, 2, 104.1, cache) == [0, 600]


def test_a_read_with_a_live_register_is_never_kept() -> None:
    regs = RegisterMap(SJ300)
    state = _state()
    cache: ReadCache = {}
    state.lease.holder, state.lease.expires_at = "10.0.0.9", 12.5
    assert regs.read(state.served, 1000, 2, 10.0, cache) == [1, 25]
    assert regs.read(state.served, 1000, 2, 11.0, cache) == [1, 15]  # same snapshot, lease aged
    assert regs.read(state.served, 0, 4, 10.0, cache) == [0, 65535, 1, 1]  # the sample's age
    assert cache == {}


def test_a_units_cache_keeps_a_bounded_number_of_reads() -> None:
    codes = [f"A{n:03d}" for n in range(1, MAX_CACHED_READS + 5)]
    regs = RegisterMap(SJ300, codes)
    state = _state()
    cache: ReadCache = {}
    for code in codes:
        state.readings.set_parameter(code, 500, 99.0)
    state.rebuild(99.0)
    for code in codes:  # a client reading every parameter on its own
        address = parameter_address(SJ300, code)
        assert address is not None
        assert regs.read(state.served, address, 2, 100.0, cache) == [0, 500]
    assert len(cache) == MAX_CACHED_READS
    # The reads kept longest made room: a client that scanned the map once leaves the
    # SCADA's own blocks room to be kept.
    last = parameter_address(SJ300, codes[-1])
    assert (last, 2) in cache
    assert (12002, 2) not in cache  # A001, the first read
    assert regs.read(state.served, 12002, 2, 100.0, cache) == [0, 500]
    assert (12002, 2) in cache
    assert len(cache) == MAX_CACHED_READS


def test_a_trip_history_is_served_until_the_served_view_s_deadline() -> None:
    """The trip registers are fresh until the served view says (its read interval past
    stale_after_s): a history read on plan is never refused as stale between two reads."""
    regs = RegisterMap(FR700)
    line = LineConfig("l", "sim://", "fr700", (1,), unit_offset=0, trips_interval_s=30.0)
    state = GatewayDrive(line, 1, FR700, Lease(5.0), stale_after_s=5.0)
    state.readings.trip_log = TripLog(1, (Trip("E.OC1", 0x10, None, None),))
    state.readings.trips_at = 0.0
    state.rebuild(0.0)
    served = state.served
    assert served.trips_until == 35.0
    assert regs.read(served, 301, 2, 20.0) == [1, 0x10]  # past stale_after_s, on plan
    assert regs.read(served, 301, 2, 35.0) == [1, 0x10]
    assert regs.read(served, 301, 2, 35.1) == Exc.TARGET_FAILED


def test_a_refused_parameter_is_refused_and_a_read_follows_the_served_view() -> None:
    regs = RegisterMap(SJ300, ["A004"])
    state = _state()
    state.readings.set_parameter("A004", 500, 99.0)
    state.rebuild(99.0)
    assert state.served.parameter_until("A004") == 104.0
    assert regs.read(state.served, 12008, 2, 104.0) == [0, 500]
    state.readings.parameters.pop("A004")
    state.readings.parameters_at.pop("A004")
    state.readings.unavailable.add("A004")
    state.rebuild(100.0)
    assert state.served.parameter_until("A004") == -math.inf
    assert regs.read(state.served, 12008, 2, 100.0) == Exc.TARGET_FAILED


def test_a_profile_register_is_fresh_as_its_read_group() -> None:
    # A profile names each register's read group; the served view judges it as that group.
    for group in ("trips", "status"):
        field = _protocol_field(RegisterField(500, "x", "1", lambda s: 0, group))
        assert field.until is _UNTIL[group]
    live = _protocol_field(RegisterField(500, "x", "1", lambda s: 0))
    assert live.until is None  # a live value: never stale
    fields = [f for name in ("sj300", "fr700") for f in get_profile(name).registers.fields]
    assert fields
    assert all(f.group is not None for f in fields)  # every built-in value is read
