"""The public names of the FR-700 subpackages are pinned, and each is what it claims."""

from __future__ import annotations

import dataclasses
import enum
import inspect
from types import ModuleType
from typing import cast

import pytest

import sj300_async.fr700 as fr700
import sj300_async.fr700.codec as fr700_codec
import sj300_async.simulator.fr700 as sim_fr700

FR700_NAMES = {
    "A1_INSTRUCTIONS", "DEFAULT_LINE_OPTIONS", "FR700_PARAMETERS", "MAX_FRAME", "MAX_REPLY_DATA",
    "MAX_STATION", "MIN_STATION", "PARAMETER_RAW_MAX", "RESET_DATA", "Fr700Ack", "Fr700Data",
    "Fr700Dialect", "Fr700Drive", "Fr700Instruction", "Fr700LineOptions", "Fr700Monitor",
    "Fr700MultiReceive", "Fr700MultiReply", "Fr700Nak", "Fr700NakCode", "Fr700OperationMode",
    "Fr700ParameterInfo", "Fr700ParserEvent", "Fr700Reply", "Fr700ReplyParser", "Fr700Request",
    "Fr700RequestKind", "Fr700Status", "Fr700StatusBits", "decode_frame", "decode_hex",
    "decode_multi_reply", "encode_ack", "encode_data_reply", "encode_host_ack", "encode_nak",
    "encode_reoutput_request", "encode_request", "fr700_parameter_info", "parameter_number",
    "parse_station", "requests", "sum_check",
    # the fault history (H74..H77)
    "FAULT_HISTORY_DEPTH", "Fr700Fault", "Fr700FaultHistory", "decode_fault_history",
    # for the simulated drives: frame bytes, the terminator, the drives' request parser
    "ETX", "STX", "terminator_bytes", "BadRequest", "HostAnswer", "HostRequest", "RequestParser",
}  # fmt: skip
#: The package's names that load the async stack: not in its sans-IO face, ``fr700.codec``.
FR700_ASYNC_NAMES = {"Fr700Dialect", "Fr700Drive"}
SIMULATOR_NAMES = {
    "DEFAULT_PROCESSING_S", "PARAMETERS", "BadRequest", "FaultCode", "Fr700SimulatedBus",
    "Fr700SimulatedDrive", "Fr700SimulatorStats", "HostAnswer", "HostRequest", "ParameterSpec",
    "RequestParser", "corrupt", "simulate", "COMMAND_LINE",
}  # fmt: skip


def public_names(module: ModuleType) -> list[str]:
    return cast(list[str], vars(module)["__all__"])


def undocumented(module: ModuleType) -> list[str]:
    """The classes, functions and modules in *module*'s ``__all__`` with no docstring of their own.

    A dataclass's generated signature and an enum's default text do not count.
    """
    missing = []
    for name in public_names(module):
        obj = getattr(module, name)
        if inspect.isclass(obj):
            doc = obj.__dict__.get("__doc__")
            if dataclasses.is_dataclass(obj) and doc and doc.startswith(f"{obj.__name__}("):
                doc = None
            if issubclass(obj, enum.Enum) and doc and doc.startswith("An enumeration"):
                doc = None
        elif inspect.isfunction(obj) or inspect.isbuiltin(obj) or inspect.ismodule(obj):
            doc = obj.__doc__
        else:
            continue  # a constant, an alias or an instance: documented where it is defined
        if not (isinstance(doc, str) and doc.strip()):
            missing.append(name)
    return missing


@pytest.mark.parametrize(
    ("module", "names"),
    [
        (fr700, FR700_NAMES),
        (fr700_codec, FR700_NAMES - FR700_ASYNC_NAMES),
        (sim_fr700, SIMULATOR_NAMES),
    ],
)
def test_all_is_pinned_importable_and_documented(module: ModuleType, names: set[str]) -> None:
    exported = public_names(module)
    assert len(exported) == len(set(exported))
    assert set(exported) == names
    for name in exported:
        assert getattr(module, name) is not None, name
    assert undocumented(module) == []


def test_fr700_all_is_pinned_and_importable() -> None:
    assert set(fr700.__all__) == FR700_NAMES
    for name in fr700.__all__:
        assert getattr(fr700, name) is not None


def test_simulator_fr700_all_is_pinned_and_importable() -> None:
    assert set(sim_fr700.__all__) == SIMULATOR_NAMES
    for name in sim_fr700.__all__:
        assert getattr(sim_fr700, name) is not None


def test_the_codec_face_is_the_package_without_its_async_names() -> None:
    # fr700.codec is what sans-IO code imports; the package adds the dialect and the drive.
    assert set(fr700_codec.__all__) == FR700_NAMES - FR700_ASYNC_NAMES
    for name in fr700_codec.__all__:
        assert getattr(fr700, name) is getattr(fr700_codec, name), name
    for name in ("BadRequest", "HostAnswer", "HostRequest", "RequestParser"):
        assert getattr(sim_fr700, name) is getattr(fr700, name), name


def test_the_root_reexports_the_fr700_objects() -> None:
    import sj300_async

    for name in ("Fr700Drive", "Fr700Monitor", "Fr700Status"):
        assert getattr(sj300_async, name) is getattr(fr700, name)


def test_events_and_results_are_frozen_and_slotted() -> None:
    classes: tuple[type, ...] = (
        fr700.Fr700Ack, fr700.Fr700Nak, fr700.Fr700Data, fr700.Fr700Request,
        fr700.Fr700Status, fr700.Fr700Monitor, fr700.Fr700MultiReply, fr700.Fr700LineOptions,
        fr700.Fr700Fault, fr700.Fr700FaultHistory,
        sim_fr700.HostRequest, sim_fr700.HostAnswer, sim_fr700.BadRequest,
    )  # fmt: skip
    for cls in classes:
        params = vars(cls)["__dataclass_params__"]
        assert params.frozen, cls
        assert "__slots__" in cls.__dict__, cls
