"""The OPC UA server through an independent client: node-opcua (tests/opcua/node/client.mjs).

asyncua is both the server and the other tests' client; a second
implementation catches what two halves of one library would agree on
wrongly: the address space as another stack browses it, the encoding of
units, ranges, timestamps and status codes, the secure channel with a
certificate asyncua did not make, and the subscriptions' notifications.

Each test runs the gateway in its own task and the node script as a
subprocess (``asyncio.create_subprocess_exec``: the loop keeps serving the
gateway meanwhile); one run of the script is one session doing the listed
steps in order, answering one JSON object. The client's PKI (its own
certificate, made once per test session, and the server certificates it
accepted) is copied into each test's directory.

``make node-packages`` (part of ``make test``) installs node-opcua from
tests/opcua/node/package-lock.json.
"""

from __future__ import annotations

import asyncio
import itertools
import json
import math
import shutil
import subprocess
import time
from collections.abc import Iterator
from dataclasses import dataclass
from datetime import datetime
from pathlib import Path
from typing import Any

import pytest
from cryptography import x509
from cryptography.hazmat.primitives import serialization
from waiting import wait_for

from sj300_async import Direction
from sj300_async.gateway import Gateway, GatewayDrive
from sj300_async.gateway.opcua._server import OpcuaServer
from sj300_async.simulator import serve_tcp
from sj300_async.simulator.sj300 import SimulatedBus

from .conftest import NAMESPACE, PASSWORD, USER, Pair, opcua_gateway, opcua_toml

NODE_DIR = Path(__file__).resolve().parent / "node"
CLIENT = NODE_DIR / "client.mjs"
#: A node run's whole deadline (the script's own is a little shorter, so it answers first).
RUN_TIMEOUT_S = 60.0

#: UNECE common codes as OPC UA UnitIds (Part 8, 5.6.3): "HTZ", "AMP", "SEC".
UNIT_HZ = 4740186
UNIT_A = 4279632
UNIT_S = 5457219
UNITS_NAMESPACE = "http://www.opcfoundation.org/UA/units/un/cefact"

Json = dict[str, Any]


def nid(path: str) -> str:
    """A node of the gateway's namespace by its path, as the script takes it."""
    return f"nsu={NAMESPACE};s={path}"


def _node_path() -> str:
    path = shutil.which("node")
    if path is None:
        raise RuntimeError("node is not installed (the tests need Node.js >= 20 and npm)")
    if not (NODE_DIR / "node_modules" / "node-opcua-client").is_dir():
        raise RuntimeError("node-opcua is not installed: make node-packages")
    return path


def _command(request: Json) -> list[str]:
    request = {"timeoutMs": int((RUN_TIMEOUT_S - 10) * 1000), **request}
    return [_node_path(), str(CLIENT), json.dumps(request)]


def _answer(returncode: int | None, out: bytes, err: bytes) -> Json:
    """The script's one JSON object (checked against its exit status)."""
    tail = err.decode(errors="replace")[-3000:]
    assert returncode in (0, 1), f"node-opcua exited {returncode}: {tail}"
    try:
        answer: Json = json.loads(out)
    except json.JSONDecodeError:
        raise AssertionError(f"node-opcua printed no JSON: {out!r}\n{tail}") from None
    assert answer["ok"] == (returncode == 0), answer
    return answer


async def run_node(request: Json, directory: Path) -> Json:
    """Run the script on *request*; its JSON answer (``ok`` false: its error)."""
    process = await asyncio.create_subprocess_exec(
        *_command(request),
        cwd=directory,
        stdin=asyncio.subprocess.DEVNULL,
        stdout=asyncio.subprocess.PIPE,
        stderr=asyncio.subprocess.PIPE,
    )
    try:
        async with asyncio.timeout(RUN_TIMEOUT_S):
            out, err = await process.communicate()
    except TimeoutError:
        process.kill()
        await process.wait()
        raise AssertionError(f"node-opcua gave no answer in {RUN_TIMEOUT_S} s") from None
    return _answer(process.returncode, out, err)


def client_certificate(pki: Path) -> Path:
    """node-opcua's own certificate (PEM) in its PKI."""
    return pki / "own" / "certs" / "client_certificate.pem"


@pytest.fixture(scope="session")
def _node_pki(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """node-opcua's PKI with its client certificate, made once (the RSA key is the slow part)."""
    directory = tmp_path_factory.mktemp("node-pki")
    pki = directory / "pki"
    # No endpoint: the script makes the certificate and connects nowhere (no loop runs
    # in a fixture's set-up: a plain subprocess).
    done = subprocess.run(
        _command({"pki": str(pki)}), cwd=directory, capture_output=True, timeout=RUN_TIMEOUT_S
    )
    answer = _answer(done.returncode, done.stdout, done.stderr)
    assert answer["ok"], answer
    assert Path(answer["certificate"]) == client_certificate(pki)
    assert client_certificate(pki).is_file()
    return pki


@dataclass
class NodeClient:
    """node-opcua runs against one server, from one PKI (in the test's directory)."""

    endpoint: str
    pki: Path
    directory: Path

    async def run(
        self,
        steps: list[Json],
        *,
        mode: str = "None",
        user: str | None = None,
        password: str | None = None,
    ) -> Json:
        """One session's steps; the answer, whether it went through or not."""
        request: Json = {
            "endpoint": self.endpoint,
            "pki": str(self.pki),
            "securityMode": mode,
            "steps": steps,
        }
        if user is not None:
            request |= {"user": user, "password": password or ""}
        return await run_node(request, self.directory)

    async def steps(
        self,
        steps: list[Json],
        *,
        mode: str = "None",
        user: str | None = None,
        password: str | None = None,
    ) -> list[Json]:
        """One session's steps' results (each step must go through)."""
        answer = await self.run(steps, mode=mode, user=user, password=password)
        assert answer["ok"], answer
        results: list[Json] = answer["steps"]
        assert [r["op"] for r in results] == [s["op"] for s in steps]
        return results

    async def operator(self, steps: list[Json]) -> list[Json]:
        """The steps as the configured user over SignAndEncrypt (what writes need)."""
        return await self.steps(steps, mode="SignAndEncrypt", user=USER, password=PASSWORD)


@pytest.fixture
def node_pki(_node_pki: Path, tmp_path: Path) -> Path:
    """This test's copy of node-opcua's PKI."""
    pki = tmp_path / "node-pki"
    shutil.copytree(_node_pki, pki)
    return pki


def node_client(server_url: str, pki: Path) -> NodeClient:
    return NodeClient(server_url, pki, pki.parent)


# -- the steps, as the script spells them -----------------------------------------------------


def read(*paths: str) -> Json:
    return {"op": "read", "nodeIds": [nid(path) for path in paths]}


def call(drive: str, method: str, *arguments: tuple[str, object]) -> Json:
    return {
        "op": "call",
        "objectId": nid(drive),
        "methodId": nid(f"{drive}/{method}"),
        "inputArguments": [{"dataType": kind, "value": value} for kind, value in arguments],
    }


def write(path: str, kind: str, value: object) -> Json:
    return {"op": "write", "nodeId": nid(path), "dataType": kind, "value": value}


def _target(step: Json) -> str:
    """The node a step calls or writes (to name it in a failure)."""
    return str(step.get("methodId") or step["nodeId"])


def statuses(results: list[Json]) -> list[str]:
    return [result["statusCode"] for result in results]


def when(text: str | None) -> float:
    """An ISO timestamp of the script as Unix time."""
    assert text is not None
    return datetime.fromisoformat(text).timestamp()


def children(node: Json) -> dict[str, Json]:
    """A browsed node's children by browse name (without the namespace index)."""
    found = {child["browseName"].split(":", 1)[1]: child for child in node["children"]}
    assert len(found) == len(node["children"]), "two children of one browse name"
    return found


def walk(node: Json, *names: str) -> Json:
    for name in names:
        node = children(node)[name]
    return node


def drive(gateway: Gateway, node: int) -> GatewayDrive:
    found = gateway.drive("hall", node)
    assert found is not None
    return found


def _fresh(gateway_drive: GatewayDrive, since: float) -> bool:
    """The drive is online with its status and monitor read after loop time *since*."""
    snapshot = gateway_drive.snapshot
    return snapshot.online and min(snapshot.status_at, snapshot.monitor_at) > since


async def polled(gateway: Gateway) -> None:
    """Once every drive has had a first good sample (its variables have values)."""
    await wait_for(
        lambda: all(d.snapshot.available and d.snapshot.monitor_at > -math.inf
                    for d in gateway.drives),
        "a first good sample of every drive",
    )  # fmt: skip


def _paths(node: Json, prefix: str = "") -> Iterator[tuple[str, str]]:
    """(node id, browse path below *node*) of every node of a browsed tree."""
    for child in node.get("children", ()):
        path = prefix + child["browseName"].split(":", 1)[1]
        yield child["nodeId"], path
        yield from _paths(child, f"{path}/")


# -- the address space ------------------------------------------------------------------------


async def test_node_opcua_browses_lines_drives_and_their_variables_by_their_names(
    tmp_path: Path, node_pki: Path
) -> None:
    async with opcua_gateway(opcua_toml(tmp_path)) as (_, server):
        node_count = server.node_count
        client = node_client(server.url, node_pki)
        namespaces, objects, lines, arguments = await client.steps(
            [
                {"op": "namespaces"},
                {"op": "browse", "nodeId": "i=85"},  # the Objects folder
                {"op": "browse", "nodeId": nid("Lines"), "depth": 6},
                read("hall/Drive1/Run/InputArguments", "hall/Drive1/SetFrequency/InputArguments"),
            ]
        )
    ns = namespaces["namespaces"].index(NAMESPACE)
    assert ns == server.namespace
    folder = children(objects["node"])["Lines"]
    assert (folder["browseName"], folder["nodeClass"]) == (f"{ns}:Lines", "Object")
    assert folder["nodeId"] == f"ns={ns};s=Lines"

    tree = lines["node"]
    assert set(children(tree)) == {"hall"}
    hall = walk(tree, "hall")
    assert set(children(hall)) >= {
        *("Protocol", "Url", "Connected", "DrivesOnline", "Utilisation", "Requests"),
        *("Replies", "Timeouts", "Retries", "LatencyMean"),
        *("Drive1", "Drive2", "Drive3", "Drive4"),
    }
    methods = {"TakeControl", "Run", "Stop", "SetFrequency"}
    for number in range(1, 5):
        drive_node = walk(hall, f"Drive{number}")
        assert drive_node["nodeClass"] == "Object"
        names = set(children(drive_node))
        assert names >= {"Line", "Node", "Protocol", "UnitId", "Online"}
        assert names >= {"Monitoring", "Logbook", "Parameters"}
        # Control is granted to drives 1 and 2 only: the others have no methods.
        assert (names & methods) == (methods if number <= 2 else set())
    drive1 = walk(hall, "Drive1")
    assert {walk(drive1, m)["nodeClass"] for m in methods} == {"Method"}
    assert walk(drive1, "Online")["nodeClass"] == "Variable"

    monitoring = walk(drive1, "Monitoring")
    assert set(children(monitoring)) >= {
        "ConverterOutputFrequency", "FrequencyCommandValue", "ConverterOutputCurrent",
        "ConverterOutputVoltage", "ShaftTurningDirection", "Running", "Tripped", "State",
    }  # fmt: skip
    frequency = walk(monitoring, "ConverterOutputFrequency")
    assert frequency["nodeClass"] == "Variable"
    assert frequency["typeDefinition"] == "ns=0;i=17497"  # AnalogUnitType
    # The standard's properties have the standard's (namespace 0) browse names.
    assert {c["browseName"] for c in frequency["children"]} == {"0:EngineeringUnits", "0:EURange"}
    shaft = walk(monitoring, "ShaftTurningDirection")
    assert shaft["typeDefinition"] == "ns=0;i=2376"  # MultiStateDiscreteType
    assert {c["browseName"] for c in shaft["children"]} == {"0:EnumStrings"}

    logbook = walk(drive1, "Logbook")
    assert set(children(logbook)) == {
        "ActiveTrip", "TripCount", "TripCodes", "TripMeanings", "TripOutputFrequencies",
        "TripOutputCurrents", "TripOutputVoltages",
    }  # fmt: skip
    trip_frequencies = walk(logbook, "TripOutputFrequencies")
    assert trip_frequencies["typeDefinition"] == "ns=0;i=17497"  # AnalogUnitType, an array
    assert {c["browseName"] for c in trip_frequencies["children"]} == {"0:EngineeringUnits"}
    assert set(children(walk(drive1, "Parameters"))) == {"A004", "F002"}
    assert set(children(walk(hall, "Drive3", "Parameters"))) == {"A004", "F002"}

    # Every node id of the gateway is its browse path (stable across restarts).
    paths = list(_paths(tree))
    assert len(paths) + 1 == node_count  # every node of the namespace, under Lines
    assert [node_id for node_id, _ in paths] == [f"ns={ns};s={path}" for _, path in paths]

    run, set_frequency = arguments["values"]
    assert run["statusCode"] == "Good"
    [direction] = run["value"]
    assert (direction["name"], direction["dataType"]) == ("Direction", "ns=0;i=12")  # String
    [hz] = set_frequency["value"]
    assert (hz["name"], hz["dataType"]) == ("Frequency", "ns=0;i=11")  # Double


# -- values: units, ranges, timestamps, quality ---------------------------------------------


async def test_values_read_good_with_their_units_and_ranges(tmp_path: Path, node_pki: Path) -> None:
    monitoring = "hall/Drive1/Monitoring"
    async with opcua_gateway(opcua_toml(tmp_path)) as (gateway, server):
        await polled(gateway)
        client = node_client(server.url, node_pki)
        values, hz, amps, seconds, state, shaft = await client.steps(
            [
                read(
                    f"{monitoring}/ConverterOutputFrequency",
                    f"{monitoring}/ConverterOutputCurrent",
                    f"{monitoring}/State",
                    f"{monitoring}/Running",
                    "hall/Drive1/Parameters/F002",
                    "hall/Drive1/Online",
                    "hall/Drive1/Node",
                ),
                {"op": "properties", "nodeId": nid(f"{monitoring}/ConverterOutputFrequency")},
                {"op": "properties", "nodeId": nid(f"{monitoring}/ConverterOutputCurrent")},
                {"op": "properties", "nodeId": nid("hall/Drive1/Parameters/F002")},
                {"op": "properties", "nodeId": nid(f"{monitoring}/State")},
                {
                    "op": "properties",
                    "nodeId": nid(f"{monitoring}/ShaftTurningDirection"),
                    "names": ["EnumStrings"],
                },
            ]
        )
        snapshot = drive(gateway, 1).snapshot
        profile = drive(gateway, 1).profile
    frequency, _, state_value, running, f002, online, node = values["values"]
    assert [v["statusCode"] for v in values["values"]] == ["Good"] * 7
    assert [v["dataType"] for v in values["values"]] == [
        "Double", "Double", "String", "Boolean", "Double", "Boolean", "Int32",
    ]  # fmt: skip
    # A stopped drive: what the gateway itself read.
    assert frequency["value"] == 0.0 == snapshot.output_frequency_hz
    assert state_value["value"] == snapshot.state_text()
    assert running["value"] is False
    assert f002["value"] == snapshot.parameters["F002"].value == 30.0  # the factory's 30 s
    assert (online["value"], node["value"]) == (True, 1)

    def units(answer: Json) -> Json:
        found: Json = answer["properties"]["EngineeringUnits"]
        assert found["statusCode"] == "Good"
        assert found["value"]["namespaceUri"] == UNITS_NAMESPACE
        return found

    hz_units = units(hz)["value"]
    assert hz_units["unitId"] == UNIT_HZ
    assert (hz_units["displayName"]["text"], hz_units["description"]["text"]) == ("Hz", "hertz")
    assert hz["properties"]["EURange"]["value"] == {
        "low": 0.0,
        "high": float(profile.max_frequency_hz),
    }
    amp_units = units(amps)["value"]
    assert (amp_units["unitId"], amp_units["displayName"]["text"]) == (UNIT_A, "A")
    assert "EURange" in amps["properties"]
    assert amps["properties"]["EURange"]["statusCode"] != "Good"  # no range for a current
    second_units = units(seconds)["value"]
    assert (second_units["unitId"], second_units["displayName"]["text"]) == (UNIT_S, "s")
    spec = profile.parameters.spec("F002")
    assert seconds["properties"]["EURange"]["value"] == {
        "low": float(spec.minimum),
        "high": float(spec.maximum),
    }
    # Text has no unit: the property is not there at all.
    assert state["properties"]["EngineeringUnits"]["statusCode"] == "BadNoMatch"
    enum = shaft["properties"]["EnumStrings"]
    assert [text["text"] for text in enum["value"]] == ["stopped", "forward", "reverse"]


async def test_a_value_is_stamped_with_the_time_it_was_read_from_the_drive(
    tmp_path: Path, node_pki: Path
) -> None:
    # The trip history is read at start and then not for ten minutes: its
    # values keep that read's time (and stay Good for a minute).
    text = opcua_toml(
        tmp_path, gateway_extra="stale_after_s = 60", line_extra="trips_interval_s = 600"
    )
    async with opcua_gateway(text) as (gateway, server):
        await polled(gateway)
        drive1 = drive(gateway, 1)
        await wait_for(lambda: drive1.snapshot.trips_at > -math.inf, "the trip history read")
        trips_at = drive1.snapshot.trips_at
        loop = asyncio.get_running_loop()
        await wait_for(lambda: loop.time() - trips_at > 0.5, "the history half a second old")
        client = node_client(server.url, node_pki)
        before = time.time()
        [answer] = await client.steps(
            [
                read(
                    "hall/Drive1/Logbook/TripCount",
                    "hall/Drive1/Monitoring/ConverterOutputFrequency",
                    "hall/Drive1/Online",
                )
            ]
        )
        after = time.time()
        snapshot = drive1.snapshot
    assert snapshot.trips_at == trips_at, "the history was read again meanwhile"
    trips_read = snapshot.time - (snapshot.taken_at - trips_at)
    trip_count, frequency, online = answer["values"]
    assert [v["statusCode"] for v in answer["values"]] == ["Good"] * 3
    assert trip_count["value"] == 0
    served = when(trip_count["serverTimestamp"])
    assert before - 0.002 <= served <= after + 0.002  # the ServerTimestamp is the read's
    # The SourceTimestamp is the history's read (to the millisecond the client keeps)...
    assert abs(when(trip_count["sourceTimestamp"]) - trips_read) < 0.005
    # ... not the read's: that came at least half a second later.
    assert served - when(trip_count["sourceTimestamp"]) > 0.5
    # The output frequency was read in a later sample, at most a few samples (0.1 s) back.
    sampled = when(frequency["sourceTimestamp"])
    assert when(trip_count["sourceTimestamp"]) < sampled <= when(frequency["serverTimestamp"])
    assert when(frequency["serverTimestamp"]) - sampled < 1.0
    assert when(online["sourceTimestamp"]) <= when(online["serverTimestamp"])


async def test_a_drive_off_the_line_reads_bad_no_communication_until_it_answers_again(
    tmp_path: Path, node_pki: Path
) -> None:
    sim = SimulatedBus(range(1, 5))
    async with await serve_tcp(sim) as line:
        text = opcua_toml(tmp_path, url=f"tcp://127.0.0.1:{line.port}")
        async with opcua_gateway(text) as (gateway, server):
            await polled(gateway)
            client = node_client(server.url, node_pki)
            sim.faults.silence(2)
            await wait_for(
                lambda: not drive(gateway, 2).snapshot.online, "drive 2 offline", timeout=15
            )
            paths = (
                "hall/Drive2/Monitoring/ConverterOutputFrequency",
                "hall/Drive2/Monitoring/State",
                "hall/Drive2/Online",
                "hall/Drive1/Monitoring/ConverterOutputFrequency",
            )
            off, run, frequency = await client.operator(
                [
                    read(*paths),
                    call("hall/Drive2", "Run", ("String", "forward")),
                    call("hall/Drive2", "SetFrequency", ("Double", 10.0)),
                ]
            )
            sim.faults.silence(2, False)
            back_at = asyncio.get_running_loop().time()
            await wait_for(lambda: _fresh(drive(gateway, 2), back_at), "drive 2 back", timeout=15)
            [back] = await client.steps([read(*paths)])
    frequency_off, state_off, online_off, other = off["values"]
    # Bad carries no value (Part 4, 7.7.1); the verdict itself is Good and says false.
    assert (frequency_off["statusCode"], frequency_off["value"]) == ("BadNoCommunication", None)
    assert (state_off["statusCode"], state_off["value"]) == ("BadNoCommunication", None)
    assert (online_off["statusCode"], online_off["value"]) == ("Good", False)
    assert other["statusCode"] == "Good"
    # Nothing moving is sent to a drive the poller holds offline.
    assert statuses([run, frequency]) == ["BadNoCommunication"] * 2
    assert [v["statusCode"] for v in back["values"]] == ["Good"] * 4
    assert back["values"][2]["value"] is True
    assert back["values"][0]["value"] == 0.0


# -- subscriptions, methods, writes ---------------------------------------------------------


async def test_a_subscription_follows_the_output_frequency_as_the_drive_runs_up(
    tmp_path: Path, node_pki: Path
) -> None:
    frequency = "hall/Drive1/Monitoring/ConverterOutputFrequency"
    async with opcua_gateway(opcua_toml(tmp_path)) as (gateway, server):
        await polled(gateway)
        client = node_client(server.url, node_pki)
        started, lease, ramp, set_frequency, run, rising, stop = await client.operator(
            [
                {
                    "op": "subscribe",
                    "id": "hz",
                    "background": True,
                    "nodeId": nid(frequency),
                    "publishingInterval": 50,
                    "until": {"gt": 20.0},
                    "timeoutMs": 20000,
                },
                call("hall/Drive1", "TakeControl"),
                write("hall/Drive1/Parameters/F002", "Double", 1.0),  # 1 s to full speed
                call("hall/Drive1", "SetFrequency", ("Double", 30.0)),
                call("hall/Drive1", "Run", ("String", "forward")),
                {"op": "wait", "id": "hz"},
                call("hall/Drive1", "Stop"),
            ]
        )
        drive1 = drive(gateway, 1)
        await wait_for(lambda: drive1.snapshot.set_frequency_hz == 30.0, "the set frequency read")
    assert started["started"] is True
    assert statuses([lease, ramp, set_frequency, run, stop]) == ["Good"] * 5
    [lease_seconds] = lease["outputArguments"]
    assert lease_seconds["dataType"] == "Double"
    assert lease_seconds["value"] == drive1.lease.duration_s > 0

    assert rising["reason"] == "until", rising
    notes = rising["notifications"]
    assert all(n["statusCode"] == "Good" and n["dataType"] == "Double" for n in notes)
    values = [n["value"] for n in notes]
    # From standstill (the first notification is the value when the item was made)...
    assert values[0] == 0.0
    # ... up, one changed sample per notification, to past 20 Hz.
    assert values[-1] > 20.0
    assert all(a < b for a, b in itertools.pairwise(values[1:])), values
    assert len({v for v in values if 0.0 < v < 20.0}) >= 2, values
    sources = [when(n["sourceTimestamp"]) for n in notes]
    assert all(a < b for a, b in itertools.pairwise(sources)), sources
    # Each sample was read from the drive before the client received it.
    for note, source in zip(notes, sources, strict=True):
        assert source <= when(note["receivedAt"]) + 0.002, note


async def test_methods_need_a_named_user_the_lease_and_an_encrypted_channel(
    tmp_path: Path, node_pki: Path
) -> None:
    drive2 = "hall/Drive2"
    async with opcua_gateway(opcua_toml(tmp_path)) as (gateway, server):
        await polled(gateway)
        client = node_client(server.url, node_pki)
        # Anonymous: nothing, whatever the channel.
        anonymous = await client.steps(
            [
                call(drive2, "TakeControl"),
                call(drive2, "Run", ("String", "forward")),
                write(f"{drive2}/Parameters/F002", "Double", 2.0),
            ],
            mode="SignAndEncrypt",
        )
        # The user over a channel that signs but does not encrypt, or over none.
        signed = await client.steps(
            [call(drive2, "TakeControl"), call(drive2, "SetFrequency", ("Double", 10.0))],
            mode="Sign",
            user=USER,
            password=PASSWORD,
        )
        plain = await client.steps(
            [call(drive2, "TakeControl"), write(f"{drive2}/Parameters/F002", "Double", 2.0)],
            mode="None",
            user=USER,
            password=PASSWORD,
        )
        refused_by = asyncio.get_running_loop().time()
        # The user over SignAndEncrypt: the lease first, then the drive runs.
        operator = await client.operator(
            [
                call(drive2, "Run", ("String", "forward")),
                call(drive2, "SetFrequency", ("Double", 12.5)),
                call(drive2, "TakeControl"),
                call(drive2, "SetFrequency", ("Double", 12.5)),
                call(drive2, "Run", ("String", "reverse")),
            ]
        )
        drive_2 = drive(gateway, 2)
        await wait_for(
            lambda: (drive_2.snapshot.running, drive_2.snapshot.direction,
                     drive_2.snapshot.set_frequency_hz) == (True, Direction.REVERSE, 12.5),
            "drive 2 running in reverse at 12.5 Hz",
        )  # fmt: skip
        [stop] = await client.operator([call(drive2, "Stop")])
        await wait_for(lambda: drive_2.snapshot.running is False, "drive 2 stopped")
        # The refused writes of F002 left it as it was.
        f002 = drive_2.snapshot.parameters["F002"]
        assert f002.at > refused_by
        assert f002.value == 30.0
    assert statuses(anonymous) == ["BadUserAccessDenied"] * 3
    assert statuses(signed) == ["BadSecurityModeInsufficient"] * 2
    assert statuses(plain) == ["BadSecurityModeInsufficient"] * 2
    assert statuses(operator) == ["BadInvalidState", "BadInvalidState", "Good", "Good", "Good"]
    assert stop["statusCode"] == "Good"


async def test_refused_arguments_and_writes_have_their_status_codes(
    tmp_path: Path, node_pki: Path
) -> None:
    drive1 = "hall/Drive1"
    f002 = f"{drive1}/Parameters/F002"
    steps: list[tuple[Json, str]] = [
        (call(drive1, "TakeControl"), "Good"),  # what follows is refused for itself alone
        # Methods: the wrong type, NaN and infinities, finer than 0.01 Hz, no such direction,
        # arguments missing or too many.
        (call(drive1, "SetFrequency", ("Float", 30.0)), "BadTypeMismatch"),
        (call(drive1, "SetFrequency", ("String", "30")), "BadTypeMismatch"),
        (call(drive1, "SetFrequency", ("Double", "NaN")), "BadOutOfRange"),
        (call(drive1, "SetFrequency", ("Double", "Infinity")), "BadOutOfRange"),
        (call(drive1, "SetFrequency", ("Double", 12.345)), "BadOutOfRange"),
        (call(drive1, "Run", ("String", "sideways")), "BadInvalidArgument"),
        (call(drive1, "Run", ("Int32", 1)), "BadTypeMismatch"),
        (call(drive1, "SetFrequency"), "BadArgumentsMissing"),
        (call(drive1, "Stop", ("String", "now")), "BadTooManyArguments"),
        # Writes: not a number, NaN, out of the parameter's range.
        (write(f002, "String", "1.5"), "BadTypeMismatch"),
        (write(f002, "Boolean", True), "BadTypeMismatch"),
        (write(f002, "Double", "NaN"), "BadOutOfRange"),
        (write(f002, "Double", "-Infinity"), "BadOutOfRange"),
        (write(f002, "Double", 99999.0), "BadOutOfRange"),
        # Read-only: a polled parameter not granted, a monitored value, a property, a
        # line counter, the granted parameter of a drive not granted it.
        (write(f"{drive1}/Parameters/A004", "Double", 60.0), "BadNotWritable"),
        (write(f"{drive1}/Monitoring/State", "String", "running"), "BadNotWritable"),
        (write(f"{drive1}/Monitoring/ConverterOutputFrequency", "Double", 1.0), "BadNotWritable"),
        (write(f"{drive1}/Node", "Int32", 7), "BadNotWritable"),
        (write("hall/Requests", "UInt64", 0), "BadNotWritable"),
        (write("hall/Drive3/Parameters/F002", "Double", 2.0), "BadNotWritable"),
        (write("hall/Drive9/Parameters/F002", "Double", 2.0), "BadNodeIdUnknown"),
    ]
    async with opcua_gateway(opcua_toml(tmp_path)) as (gateway, server):
        await polled(gateway)
        client = node_client(server.url, node_pki)
        results = await client.operator([step for step, _ in steps])
        # Nothing refused reached a drive: the parameters read after are the factory's.
        after = asyncio.get_running_loop().time()
        drives = [drive(gateway, 1), drive(gateway, 3)]
        await wait_for(
            lambda: all(d.snapshot.parameters["F002"].at > after for d in drives),
            "F002 read again",
        )
        f002_values = [d.snapshot.parameters["F002"].value for d in drives]
        a004 = drive(gateway, 1).snapshot.parameters["A004"].value
    answered = [(_target(s), r["statusCode"]) for (s, _), r in zip(steps, results, strict=True)]
    assert answered == [(_target(s), expected) for s, expected in steps]
    assert f002_values == [30.0, 30.0]
    assert a004 != 60.0


# -- the secure channel ---------------------------------------------------------------------


async def test_node_opcuas_own_certificate_opens_the_encrypted_channel(
    tmp_path: Path, node_pki: Path
) -> None:
    trusted = tmp_path / "trusted"
    trusted.mkdir()
    shutil.copy(client_certificate(node_pki), trusted / "node-opcua.pem")
    text = opcua_toml(tmp_path, opcua_extra=f'trusted_clients = "{trusted}"')
    async with opcua_gateway(text) as (gateway, server):
        await polled(gateway)
        assert server.certificate is not None
        server_certificate = server.certificate.certificate.read_bytes()
        client = node_client(server.url, node_pki)
        [secure] = await client.operator(
            [read("hall/Drive1/Online", "hall/Drive1/Monitoring/ConverterOutputFrequency")]
        )
        wrong = await client.run(
            [read("hall/Drive1/Online")], mode="SignAndEncrypt", user=USER, password="wrong"
        )
        unknown = await client.run(
            [read("hall/Drive1/Online")], mode="SignAndEncrypt", user="nobody", password=PASSWORD
        )
        # Under trusted_clients an unsecured channel (no certificate to judge it by)
        # serves discovery only: no session on it, whatever certificate it would name.
        plain = await client.run([read("hall/Drive1/Online")])
        untrusted = server.untrusted
    assert [v["statusCode"] for v in secure["values"]] == ["Good", "Good"]
    assert not wrong["ok"]
    assert wrong["error"]["statusCode"] == "BadUserAccessDenied"
    assert not unknown["ok"]
    assert unknown["error"]["statusCode"] == "BadUserAccessDenied"
    assert not plain["ok"]
    assert plain["error"]["statusCode"] == "BadSecurityPolicyRejected"
    assert untrusted == 0
    # node-opcua accepted the server's own certificate (and only it) into its PKI.
    accepted = list((node_pki / "trusted" / "certs").iterdir())
    assert len(accepted) == 1
    assert _der(accepted[0].read_bytes()) == server_certificate


async def test_a_server_trusting_other_clients_refuses_node_opcuas_certificate(
    tmp_path: Path, node_pki: Path, other_pair: Pair
) -> None:
    trusted = tmp_path / "trusted"
    trusted.mkdir()
    shutil.copy(other_pair.certificate, trusted / "other.der")
    text = opcua_toml(tmp_path, opcua_extra=f'trusted_clients = "{trusted}"')
    async with opcua_gateway(text) as (_, server):
        client = node_client(server.url, node_pki)
        refused = await client.run(
            [read("hall/Drive1/Online")], mode="SignAndEncrypt", user=USER, password=PASSWORD
        )
        refused_then = server.untrusted
        plain = await client.run([read("hall/Drive1/Online")])
    # The encrypted channel is refused as it opens (asyncua closes the connection: no
    # status code reaches the client): no session, no step ran.
    assert not refused["ok"], refused
    assert refused["steps"] == []
    assert refused_then == 1
    # Unsecured: a discovery-only channel, where CreateSession is refused before the
    # certificate it names is judged.
    assert not plain["ok"], plain
    assert plain["error"]["statusCode"] == "BadSecurityPolicyRejected"
    assert plain["steps"] == []


def _der(pem_or_der: bytes) -> bytes:
    """A certificate file's DER bytes."""
    if pem_or_der.lstrip().startswith(b"-----BEGIN"):
        return x509.load_pem_x509_certificate(pem_or_der).public_bytes(serialization.Encoding.DER)
    return pem_or_der


def _events_watched(server: OpcuaServer) -> bool:
    """Some subscription monitors events (asyncua's own tables: a test's look only)."""
    asyncua_server = server._server
    if asyncua_server is None:
        return False
    subscriptions = asyncua_server.iserver.subscription_service.subscriptions.values()
    return any(s.monitored_item_srv._monitored_events for s in subscriptions)


async def test_a_trip_record_reaches_node_opcua_as_an_event_of_the_server_object(
    tmp_path: Path, node_pki: Path
) -> None:
    text = opcua_toml(tmp_path) + "\n[recorder]\nbefore_s = 1\nafter_s = 0.5\n"
    fields = ["SourceName", "Message", "Severity", "TripCode", "RecordId"]
    async with opcua_gateway(text) as (gateway, server):
        await polled(gateway)
        client = node_client(server.url, node_pki)
        steps: list[Json] = [
            {"op": "subscribe", "id": "trips", "background": True, "nodeId": "i=2253",
             "events": fields, "until": {"count": 1}, "timeoutMs": 20000},
            {"op": "wait", "id": "trips"},
        ]  # fmt: skip
        run = asyncio.create_task(client.steps(steps))
        await wait_for(lambda: _events_watched(server) or run.done(), "the event item", timeout=30)
        simulator = gateway.lines[0].bus.simulator
        assert simulator.drives[4].trip(7, now=asyncio.get_running_loop().time())
        _, waited = await run
        assert gateway.trip_records is not None
        summary = gateway.trip_records.summaries()[0]
    assert waited["reason"] == "count"
    assert waited["notifications"] == [
        {
            "SourceName": "hall/4",
            "Message": {"locale": None, "text": f"hall/4 tripped: {summary.meaning} (E07)"},
            "Severity": 800,
            "TripCode": "E07",
            "RecordId": summary.id,
        }
    ]
