"""The public names of the FR-700 subpackages are pinned, and each is what it claims."""

from __future__ import annotations

import sj300_async.fr700 as fr700
import sj300_async.simulator.fr700 as sim_fr700

FR700_NAMES = {
    "A1_INSTRUCTIONS", "DEFAULT_LINE_OPTIONS", "MAX_FRAME", "MAX_REPLY_DATA", "MAX_STATION",
    "MIN_STATION", "RESET_DATA", "Fr700Ack", "Fr700Data", "Fr700Dialect", "Fr700Drive",
    "Fr700Instruction", "Fr700LineOptions", "Fr700Monitor", "Fr700MultiReceive",
    "Fr700MultiReply", "Fr700Nak", "Fr700NakCode", "Fr700OperationMode", "Fr700ParserEvent",
    "Fr700Reply", "Fr700ReplyParser", "Fr700Request", "Fr700RequestKind", "Fr700Status",
    "Fr700StatusBits", "decode_frame", "decode_hex", "decode_multi_reply", "encode_ack",
    "encode_data_reply", "encode_host_ack", "encode_nak", "encode_reoutput_request",
    "encode_request", "parse_station", "requests", "sum_check",
}  # fmt: skip
SIMULATOR_NAMES = {
    "DEFAULT_PROCESSING_S", "PARAMETERS", "BadRequest", "FaultCode", "Fr700SimulatedBus",
    "Fr700SimulatedDrive", "Fr700SimulatorStats", "HostAnswer", "HostRequest", "ParameterSpec",
    "RequestParser", "corrupt",
}  # fmt: skip


def test_fr700_all_is_pinned_and_importable():
    assert set(fr700.__all__) == FR700_NAMES
    for name in fr700.__all__:
        assert getattr(fr700, name) is not None


def test_simulator_fr700_all_is_pinned_and_importable():
    assert set(sim_fr700.__all__) == SIMULATOR_NAMES
    for name in sim_fr700.__all__:
        assert getattr(sim_fr700, name) is not None


def test_events_and_results_are_frozen_and_slotted():
    for cls in (
        fr700.Fr700Ack, fr700.Fr700Nak, fr700.Fr700Data, fr700.Fr700Request,
        fr700.Fr700Status, fr700.Fr700Monitor, fr700.Fr700MultiReply, fr700.Fr700LineOptions,
        sim_fr700.HostRequest, sim_fr700.HostAnswer, sim_fr700.BadRequest,
    ):  # fmt: skip
        params = cls.__dataclass_params__  # type: ignore[attr-defined]
        assert params.frozen, cls
        assert "__slots__" in cls.__dict__, cls
