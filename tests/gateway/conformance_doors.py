"""The five doors of the conformance test (test_gateway_conformance.py), each a real client.

Each door turns a neutral case (:class:`Send`: what, which drive, the
value as the client would write it) into its own wire format and sends
it over a real socket: Modbus TCP (pymodbus), MQTT JSON commands and
Sparkplug DCMDs (mosquitto_pub; Sparkplug payloads encoded by Eclipse
Tahu), OPC UA (asyncua, a named user over Basic256Sha256
SignAndEncrypt) and the HTTP write API (aiohttp, a script's token). A
door that cannot express a case says so (:data:`CANNOT`): the case
skips that door.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Final

import aiohttp
from asyncua import Client, ua
from asyncua.ua.uaerrors import UaStatusCodeError
from mqtt_broker import Broker, publish
from pymodbus.client import AsyncModbusTcpClient
from sparkplug.host import Host
from sparkplug.test_sparkplug_lifecycle import births, names

from sj300_async.gateway.modbus import parameter_address
from sj300_async.gateway.mqtt import Topics
from sj300_async.profiles import get_profile

#: What a door's answer says, when it answers at once (Modbus, OPC UA, HTTP): its words.
Answer = str | None

#: The door cannot express the case (it is skipped there): None.
CANNOT: Final = None

_PROFILE = get_profile("sj300")


@dataclass(frozen=True)
class Send:
    """One request, neutral: ``what`` is frequency, run, stop, heartbeat or parameter."""

    what: str
    node: int = 1
    #: The value as a client writes it: a float (Hz, or the parameter's unit), a
    #: direction ("forward", "reverse"), or text that is no number.
    value: object = None
    code: str = "F002"


def _number(value: object) -> float | None:
    return float(value) if isinstance(value, int | float) else None


class ModbusDoor:
    name = "modbus"

    def __init__(self, client: AsyncModbusTcpClient) -> None:
        self.client = client

    def can(self, send: Send) -> bool:
        if send.what == "run":
            return send.value in ("forward", "reverse")
        if send.what == "frequency":  # 0.01 Hz in one unsigned register
            hz = _number(send.value)
            return hz is not None and math.isfinite(hz) and _registers(hz * 100) is not None
        if send.what == "parameter":  # the drive's integer in two registers
            number = _number(send.value)
            scale = _PROFILE.parameters.spec(send.code).scale
            return number is not None and _registers(number * scale, 1 << 31) is not None
        return True

    async def send(self, send: Send) -> Answer:
        unit = send.node
        if send.what == "heartbeat":
            response = await self.client.write_register(1000, 1, device_id=unit)
        elif send.what == "stop":
            response = await self.client.write_register(1002, 0, device_id=unit)
        elif send.what == "run":
            direction = 1 if send.value == "forward" else 2
            response = await self.client.write_register(1002, direction, device_id=unit)
        elif send.what == "frequency":
            raw = _registers(float(send.value) * 100)  # type: ignore[arg-type]
            assert raw is not None
            response = await self.client.write_register(1003, raw, device_id=unit)
        else:
            scale = _PROFILE.parameters.spec(send.code).scale
            raw = _registers(float(send.value) * scale, 1 << 31)  # type: ignore[arg-type]
            address = parameter_address(_PROFILE, send.code)
            assert raw is not None
            assert address is not None
            response = await self.client.write_registers(
                address, [raw >> 16, raw & 0xFFFF], device_id=unit
            )
        return f"0x{int(response.exception_code):02X}" if response.isError() else None


def _registers(scaled: float, limit: int = 1 << 16) -> int | None:
    """*scaled* as the register's integer, None when no integer or not 0..limit."""
    if not math.isfinite(scaled) or scaled < 0:  # no sign in a register
        return None
    whole = round(scaled)
    return whole if abs(whole - scaled) < 1e-6 and 0 <= whole < limit else None


class MqttDoor:
    name = "mqtt"

    def __init__(self, broker: Broker) -> None:
        self.broker = broker
        self.topics = Topics("gw1")

    def can(self, send: Send) -> bool:
        return True

    async def send(self, send: Send) -> Answer:
        what, payload = {
            "heartbeat": ("lease", "1"),
            "stop": ("command", "stop"),
            "run": ("command", f"run_{send.value}"),
            "frequency": ("frequency_hz", _text(send.value)),
            "parameter": (send.code, _text(send.value)),
        }[send.what]
        await publish(self.broker, self.topics.command("hall", send.node, what), payload)
        return None


def _text(value: object) -> str:
    return repr(value) if isinstance(value, float) else str(value)


class SparkplugDoor:
    name = "sparkplug"

    def __init__(self, host: Host) -> None:
        self.host = host

    def can(self, send: Send) -> bool:
        number = _number(send.value)
        # Tahu's codec is driven by JSON, which carries no NaN or infinity.
        return number is None or math.isfinite(number)

    def _metric(self, node: int, name: str, kind: str, value: object) -> dict[str, Any]:
        alias = names(births(self.host, f"hall-{node}")[-1]).get(name, {}).get("alias")
        if alias is None:  # not born with it (a drive not granted): named, as a host may
            return {"name": name, "type": kind, "value": value}
        return {"alias": alias, "type": kind, "value": value}

    async def send(self, send: Send) -> Answer:
        value = send.value
        number = _number(value)
        if send.what == "heartbeat":
            metric = self._metric(send.node, "Control/Lease", "Boolean", True)
        elif send.what == "stop":
            metric = self._metric(send.node, "Control/Stop", "Boolean", True)
        elif send.what == "run":
            metric = self._metric(send.node, "Direction", "String", value)
        else:
            name = "Frequency Command" if send.what == "frequency" else f"Parameters/{send.code}"
            if number is None:
                metric = self._metric(send.node, name, "String", str(value))
            else:
                metric = self._metric(send.node, name, "Double", number)
        await self.host.command("DCMD", [metric], f"hall-{send.node}")
        return None


class OpcuaDoor:
    name = "opcua"

    def __init__(self, client: Client, namespace: int) -> None:
        self.client = client
        self.ns = namespace

    def can(self, send: Send) -> bool:
        return True

    async def send(self, send: Send) -> Answer:
        drive = self.client.get_node(ua.NodeId(f"hall/Drive{send.node}", self.ns))
        number = _number(send.value)
        variant = (
            ua.Variant(str(send.value), ua.VariantType.String)
            if number is None
            else ua.Variant(number, ua.VariantType.Double)
        )
        try:
            if send.what == "heartbeat":
                await drive.call_method(f"{self.ns}:TakeControl")
            elif send.what == "stop":
                await drive.call_method(f"{self.ns}:Stop")
            elif send.what == "run":
                direction = ua.Variant(send.value, ua.VariantType.String)
                await drive.call_method(f"{self.ns}:Run", direction)
            elif send.what == "frequency":
                await drive.call_method(f"{self.ns}:SetFrequency", variant)
            else:
                path = f"hall/Drive{send.node}/Parameters/{send.code}"
                await self.client.get_node(ua.NodeId(path, self.ns)).write_value(variant)
        except UaStatusCodeError as exc:
            return str(ua.StatusCode(exc.code).name)
        return None


class HttpDoor:
    name = "http"

    def __init__(self, session: aiohttp.ClientSession, base: str, token: str) -> None:
        self.session = session
        self.base = base
        self.headers = {"Authorization": f"Bearer {token}", "Content-Type": "application/json"}

    def can(self, send: Send) -> bool:
        return True

    async def send(self, send: Send) -> Answer:
        path, body = {
            "heartbeat": ("lease", "{}"),
            "stop": ("stop", "{}"),
            "run": ("run", f'{{"direction": "{send.value}"}}'),
            "frequency": ("frequency", f'{{"hz": {_json(send.value)}}}'),
            "parameter": ("parameter", f'{{"code": "{send.code}", "value": {_json(send.value)}}}'),
        }[send.what]
        url = f"{self.base}/api/v1/drives/hall/{send.node}/{path}"
        async with self.session.post(url, data=body.encode(), headers=self.headers) as response:
            return None if response.status == 200 else str(response.status)


def _json(value: object) -> str:
    """*value* as JSON text; NaN and infinities as Python's json writes them (NaN, Infinity)."""
    if isinstance(value, float):
        if math.isnan(value):
            return "NaN"
        if math.isinf(value):
            return "Infinity" if value > 0 else "-Infinity"
        return repr(value)
    if isinstance(value, int):
        return str(value)
    return f'"{value}"'


Door = ModbusDoor | MqttDoor | SparkplugDoor | OpcuaDoor | HttpDoor
