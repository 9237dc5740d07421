"""What gateway/opcua/_hooks.py changes in asyncua's server, each shown by a client doing it.

Each test is a way in that asyncua's defaults left open (an adversarial
review found them): an unoffered unsecured channel, a certificate left out
of CreateSession past ``trusted_clients``, a guessed session token, a
session re-activated and its lease, logins that stall the loop, a flood of
calls, discovery registration, a written status code, and our own bugs
(a value that cannot be served, a tick that fails) kept from spreading.
"""

from __future__ import annotations

import asyncio
import contextlib
import dataclasses
import math
import shutil
import socket
from pathlib import Path
from typing import Any

import pytest
from asyncua import Client, ua
from asyncua.client.ua_client import UaClient
from asyncua.ua.uaerrors import UaError, UaStatusCodeError
from waiting import wait_for

from sj300_async.gateway import Quality, ServedDrive
from sj300_async.gateway.opcua._config import DEFAULT_LOGIN_BURST
from sj300_async.gateway.opcua._server import OpcuaServer
from sj300_async.profiles import DriveSnapshot

from .conftest import (
    CLIENT_URI,
    NAMESPACE,
    PASSWORD,
    USER,
    Pair,
    connected,
    opcua_gateway,
    opcua_toml,
    polled,
    tcp_line,
    unsecured_channel,
)

SECURE_ONLY = '["Basic256Sha256_SignAndEncrypt", "Basic256Sha256_Sign"]'


async def _session_on(client: UaClient, url: str) -> None:
    """Create and activate an anonymous session on *client*'s channel."""
    params = ua.CreateSessionParameters(
        ClientNonce=b"\0" * 32,
        SessionName="probe",
        RequestedSessionTimeout=60_000,
        EndpointUrl=url,
        MaxResponseMessageSize=0,
    )
    await client.create_session(params)
    activate = ua.ActivateSessionParameters(
        UserIdentityToken=ua.AnonymousIdentityToken(PolicyId="anonymous")
    )
    await client.activate_session(activate)


def _counted(server: OpcuaServer, family: str, label: str) -> float:
    """One label's count in one of the server's metric families."""
    (found,) = [f for f in server.metrics() if f.name == family]
    return sum(s.value for s in found.samples if label in s.labels.values())


async def _read_state(client: UaClient, ns: int) -> ua.DataValue:
    read = ua.ReadValueId(
        NodeId=ua.NodeId("hall/Drive1/Monitoring/State", ns), AttributeId=ua.AttributeIds.Value
    )
    (value,) = await client.read(ua.ReadParameters(NodesToRead=[read]))
    return value


@pytest.mark.parametrize("trusted", [False, True], ids=["secure-only", "trusted-clients"])
async def test_an_unoffered_or_uncertified_unsecured_channel_only_discovers(
    tmp_path: Path, client_pair: Pair, trusted: bool
) -> None:
    """No session on it: discovery (GetEndpoints, FindServers) only."""
    extra = ""
    if trusted:  # None offered, but it carries no certificate to trust
        (tmp_path / "trusted").mkdir()
        shutil.copy(client_pair.certificate, tmp_path / "trusted" / "client.der")
        extra = f'trusted_clients = "{tmp_path / "trusted"}"'
    security = '["Basic256Sha256_SignAndEncrypt", "None"]' if trusted else SECURE_ONLY
    text = opcua_toml(tmp_path, security=security, opcua_extra=extra)
    async with opcua_gateway(text) as (_, server), unsecured_channel(server.url) as client:
        endpoints = await client.get_endpoints(ua.GetEndpointsParameters(EndpointUrl=server.url))
        assert ua.MessageSecurityMode.SignAndEncrypt in {e.SecurityMode for e in endpoints}
        with pytest.raises(UaStatusCodeError) as refused:
            await _session_on(client, server.url)
        assert ua.StatusCode(refused.value.code).name == "BadSecurityPolicyRejected"
        assert server.session_count == 0
        assert _counted(server, "sj300_opcua_refused_sessions", "discovery") == 1


async def test_an_offered_unsecured_channel_reads(tmp_path: Path) -> None:
    text = opcua_toml(tmp_path, security='["None"]')
    async with opcua_gateway(text) as (gateway, server), unsecured_channel(server.url) as client:
        await polled(gateway)
        await _session_on(client, server.url)
        assert (await _read_state(client, 1)).Value.Value == "stopped"


async def test_an_untrusted_certificate_cannot_skip_the_check_by_leaving_it_out(
    tmp_path: Path, client_pair: Pair, other_pair: Pair
) -> None:
    trusted = tmp_path / "trusted"
    trusted.mkdir()
    shutil.copy(client_pair.certificate, trusted / "client.der")
    text = opcua_toml(tmp_path, opcua_extra=f'trusted_clients = "{trusted}"')
    async with opcua_gateway(text) as (gateway, server):
        await polled(gateway)
        client = Client(server.url, timeout=5)
        client.application_uri = "urn:sj300-async:other-client"
        await client.set_security_string(
            f"Basic256Sha256,SignAndEncrypt,{other_pair.certificate},{other_pair.key}"
        )
        client.set_user(USER)
        client.set_password(PASSWORD)
        create = client.uaclient.create_session

        async def without_certificate(params: Any) -> Any:
            params.ClientCertificate = None  # the session's check would not run
            return await create(params)

        client.uaclient.create_session = without_certificate
        with pytest.raises((UaError, OSError, TimeoutError, ConnectionError)):
            await client.connect()  # refused when the channel opens
        with contextlib.suppress(Exception):
            await client.disconnect()
        drive = gateway.drive("hall", 1)
        assert drive is not None
        assert drive.lease.holder is None
        assert server.untrusted >= 1


async def test_session_tokens_are_random_and_another_s_cannot_be_activated(
    tmp_path: Path, client_pair: Pair
) -> None:
    async with (
        opcua_gateway(opcua_toml(tmp_path)) as (gateway, server),
        connected(server.url, pair=client_pair, user=USER, password=PASSWORD) as operator,
    ):
        await polled(gateway)
        token = operator.uaclient.protocol.authentication_token
        assert token.NodeIdType == ua.NodeIdType.ByteString
        assert len(token.Identifier) == 32
        # A client that guesses asyncua's counter (1000, 1001...) finds nothing to take over.
        async with unsecured_channel(server.url) as intruder:
            for guess in range(1000, 1010):
                intruder.protocol.authentication_token = ua.NodeId(guess)
                params = ua.ActivateSessionParameters(
                    UserIdentityToken=ua.AnonymousIdentityToken(PolicyId="anonymous")
                )
                with pytest.raises(UaStatusCodeError):
                    await intruder.activate_session(params)
        ns = await operator.get_namespace_index(NAMESPACE)
        drive = operator.get_node(ua.NodeId("hall/Drive1", ns))
        assert await drive.call_method(f"{ns}:TakeControl") == 5.0


async def test_a_reactivated_session_still_lapses_its_lease_when_it_closes(
    tmp_path: Path, client_pair: Pair
) -> None:
    async with tcp_line() as (sim, url):
        text = opcua_toml(tmp_path, url=url, line_extra='lease_s = 60\nlease_scope = "connection"')
        async with opcua_gateway(text) as (gateway, server):
            await polled(gateway)
            drive = gateway.drive("hall", 1)
            assert drive is not None
            async with connected(
                server.url, pair=client_pair, user=USER, password=PASSWORD
            ) as client:
                ns = await client.get_namespace_index(NAMESPACE)
                node = client.get_node(ua.NodeId("hall/Drive1", ns))
                assert await node.call_method(f"{ns}:TakeControl") == 60.0
                await client.activate_session(USER, PASSWORD)  # the same session, again
                await node.call_method(f"{ns}:SetFrequency", ua.Variant(5.0, ua.VariantType.Double))
                await node.call_method(f"{ns}:Run", "forward")
                loop = asyncio.get_running_loop()
                assert sim.drives[1].state(loop.time()).outputting
            await wait_for(lambda: drive.lease.holder is None, "the lease lapsed", timeout=5)
            await wait_for(
                lambda: not sim.drives[1].state(asyncio.get_running_loop().time()).outputting,
                "the drive stopped",
                timeout=10,
            )


async def test_an_unactivated_session_is_closed(tmp_path: Path) -> None:
    text = opcua_toml(tmp_path, security='["None"]', opcua_extra="activate_within_s = 0.5")
    async with opcua_gateway(text) as (_, server), unsecured_channel(server.url) as client:
        params = ua.CreateSessionParameters(
            ClientNonce=b"\0" * 32,
            SessionName="never activated",
            RequestedSessionTimeout=60_000,
            EndpointUrl=server.url,
            MaxResponseMessageSize=0,
        )
        await client.create_session(params)
        assert server.session_count == 1
        await wait_for(lambda: server.session_count == 0, "the session closed", timeout=5)
        assert _counted(server, "sj300_opcua_refused_sessions", "expired") == 1


async def test_failed_logins_are_throttled_and_never_stall_the_loop(tmp_path: Path) -> None:
    async with opcua_gateway(opcua_toml(tmp_path)) as (_, server):
        loop = asyncio.get_running_loop()
        stalls: list[float] = []

        async def watch() -> None:
            while True:
                before = loop.time()
                await asyncio.sleep(0.01)
                stalls.append(loop.time() - before - 0.01)

        watcher = asyncio.create_task(watch())
        client = Client(server.url, timeout=30)
        client.application_uri = CLIENT_URI
        await client.connect()  # anonymous, unsecured (the test's server offers None)
        try:

            async def wrong() -> None:
                with contextlib.suppress(UaStatusCodeError):
                    await client.activate_session(USER, "wrong")

            await asyncio.gather(*(wrong() for _ in range(30)))
        finally:
            watcher.cancel()
            with contextlib.suppress(Exception):
                await client.disconnect()
        # 30 scrypt checks in a row would hold the loop ~2 s; one address's budget allows
        # 5 at once (a sixth, maybe, as it refills), checked off the loop.
        refusals = server._users.refusals
        assert refusals["password"] + refusals["rate"] == 30
        assert refusals["rate"] >= 30 - DEFAULT_LOGIN_BURST - 1
        assert max(stalls) < 0.5, f"the loop stood still {max(stalls):.2f} s"
        assert _counted(server, "sj300_opcua_refused_logins", "rate") == refusals["rate"]


async def test_one_request_carries_at_most_64_writes(tmp_path: Path, client_pair: Pair) -> None:
    async with (
        opcua_gateway(opcua_toml(tmp_path)) as (gateway, server),
        connected(server.url, pair=client_pair, user=USER, password=PASSWORD) as client,
    ):
        await polled(gateway)
        ns = await client.get_namespace_index(NAMESPACE)
        stop = ua.CallMethodRequest(
            ObjectId=ua.NodeId("hall/Drive1", ns), MethodId=ua.NodeId("hall/Drive1/Stop", ns)
        )
        before = len(gateway.audit.recent)
        results = await client.uaclient.call([stop] * 100)
        names = [result.StatusCode.name for result in results]
        assert names == ["Good"] * 64 + ["BadTooManyOperations"] * 36
        assert len(gateway.audit.recent) - before == 64


async def test_an_array_argument_is_a_type_mismatch_and_audited(
    tmp_path: Path, client_pair: Pair
) -> None:
    async with (
        opcua_gateway(opcua_toml(tmp_path)) as (gateway, server),
        connected(server.url, pair=client_pair, user=USER, password=PASSWORD) as client,
    ):
        await polled(gateway)
        ns = await client.get_namespace_index(NAMESPACE)
        for argument in (
            ua.Variant([5.0], ua.VariantType.Double, is_array=True),
            ua.Variant([], ua.VariantType.Double, is_array=True),
            ua.Variant(["forward"], ua.VariantType.String, is_array=True),
        ):
            method = "Run" if argument.VariantType == ua.VariantType.String else "SetFrequency"
            call = ua.CallMethodRequest(
                ObjectId=ua.NodeId("hall/Drive1", ns),
                MethodId=ua.NodeId(f"hall/Drive1/{method}", ns),
                InputArguments=[argument],
            )
            before = len(gateway.audit.recent)
            (result,) = await client.uaclient.call([call])
            assert result.StatusCode.name == "BadTypeMismatch"
            assert len(gateway.audit.recent) == before + 1


async def test_discovery_registration_is_refused(tmp_path: Path) -> None:
    text = opcua_toml(tmp_path, security='["None"]')
    async with opcua_gateway(text) as (_, server), unsecured_channel(server.url) as client:
        registered = ua.RegisteredServer(
            ServerUri="urn:someone:else",
            ServerNames=[ua.LocalizedText("else")],
            DiscoveryUrls=["opc.tcp://10.6.6.6:4840"],
            IsOnline=True,
        )
        with pytest.raises(UaStatusCodeError) as refused:
            await client.register_server(registered)
        assert ua.StatusCode(refused.value.code).name == "BadServiceUnsupported"
        found = await client.find_servers(ua.FindServersParameters(EndpointUrl=server.url))
        assert [s.ApplicationUri for s in found] == [NAMESPACE]


async def test_a_value_written_with_a_bad_status_is_refused_unsent(
    tmp_path: Path, client_pair: Pair
) -> None:
    async with (
        tcp_line() as (sim, url),
        opcua_gateway(opcua_toml(tmp_path, url=url)) as (gateway, server),
        connected(server.url, pair=client_pair, user=USER, password=PASSWORD) as client,
    ):
        await polled(gateway)
        ns = await client.get_namespace_index(NAMESPACE)
        before = dict(sim.drives[1].parameters)
        flagged = ua.DataValue(
            ua.Variant(5.0, ua.VariantType.Double),
            StatusCode=ua.StatusCode(ua.StatusCodes.BadNoCommunication),
        )
        write = ua.WriteValue(
            NodeId=ua.NodeId("hall/Drive1/Parameters/F002", ns),
            AttributeId=ua.AttributeIds.Value,
            Value=flagged,
        )
        (status,) = await client.uaclient.write(ua.WriteParameters(NodesToWrite=[write]))
        assert status.name == "BadWriteNotSupported"
        assert dict(sim.drives[1].parameters) == before
        assert gateway.audit.recent[-1]["result"] == "refused"


async def test_a_value_that_cannot_be_served_fails_alone(tmp_path: Path) -> None:
    async with opcua_gateway(opcua_toml(tmp_path)) as (gateway, server):
        await polled(gateway)
        binding = next(
            b for b in server._drives[("hall", 1)].bindings
            if b.name == "Monitoring/ConverterOutputCurrent"
        )  # fmt: skip
        binding.value = "not a number"  # as a bug of ours would leave it
        binding.read = lambda s: ("not a number", s.monitor_at)
        async with connected(server.url) as client:
            ns = await client.get_namespace_index(NAMESPACE)
            nodes = [
                ua.ReadValueId(
                    NodeId=ua.NodeId(f"hall/Drive1/Monitoring/{name}", ns),
                    AttributeId=ua.AttributeIds.Value,
                )
                for name in ("ConverterOutputFrequency", "ConverterOutputCurrent")
            ]
            good, bad = await client.uaclient.read(ua.ReadParameters(NodesToRead=nodes))
            assert good.StatusCode.is_good()
            assert bad.StatusCode.name == "BadInternalError"
        assert server.push_errors >= 1


async def test_close_stops_the_server_even_after_a_tick_failed(tmp_path: Path) -> None:
    async with opcua_gateway(opcua_toml(tmp_path)) as (_, server):
        port = int(server.url.rsplit(":", 1)[1])
        errors = server.push_errors

        def boom(*args: Any) -> bool:
            raise ZeroDivisionError("injected")

        server._counters.tick = boom  # type: ignore[method-assign,assignment]
        await wait_for(lambda: server.push_errors > errors, "a failed tick", timeout=5)
        await wait_for(lambda: server.push_errors > errors + 1, "the ticks go on", timeout=5)
    with socket.socket() as probe:
        probe.settimeout(1)
        with pytest.raises(ConnectionRefusedError):  # closed: nothing listens any more
            probe.connect(("127.0.0.1", port))


async def test_monitored_items_are_followed_as_they_come_and_go(
    tmp_path: Path, client_pair: Pair
) -> None:
    """follow_watchers hears asyncua add and delete each monitored item on a value."""
    async with (
        opcua_gateway(opcua_toml(tmp_path)) as (gateway, server),
        connected(server.url, pair=client_pair, user=USER, password=PASSWORD) as client,
    ):
        await polled(gateway)
        ns = await client.get_namespace_index(NAMESPACE)
        nodes = server._drives["hall", 1]
        frequency = client.get_node(
            ua.NodeId("hall/Drive1/Monitoring/ConverterOutputFrequency", ns)
        )
        running = client.get_node(ua.NodeId("hall/Drive1/Monitoring/Running", ns))
        assert nodes.watched == 0

        class Quiet:
            def datachange_notification(self, *args: Any) -> None:
                pass

        subscription = await client.create_subscription(100, Quiet())
        handles = await subscription.subscribe_data_change([frequency, running, frequency])
        await wait_for(lambda: nodes.watched == 3, "three monitored items followed")
        by_name = {b.name: b.watched for b in nodes.bindings}
        assert by_name["Monitoring/ConverterOutputFrequency"] == 2
        assert by_name["Monitoring/Running"] == 1
        # What a sample visits: the monitor group (frequency) and the status group
        # (running), each with only its watched binding, of a dozen groups.
        visited = {b.name for g in nodes.watched_groups for b in g.watched}
        assert visited == {"Monitoring/ConverterOutputFrequency", "Monitoring/Running"}
        assert len(nodes.watched_groups) == 2 < len(nodes.groups)
        await subscription.unsubscribe(handles[0])
        await wait_for(lambda: nodes.watched == 2, "one deleted")
        await subscription.delete()
        await wait_for(lambda: nodes.watched == 0, "the subscription's items deleted with it")
        assert all(b.watched == 0 for b in nodes.bindings)
        assert nodes.watched_groups == []


async def test_a_group_watched_again_takes_the_next_sample(tmp_path: Path) -> None:
    """A group nobody watched saw no samples: watched again, it takes the next whatever its
    stamp. Found by review: the trip count, unwatched, the drive gone offline, watched again
    (asyncua's first read: offline), the drive back with its trips not read again: the
    count stayed BadNoCommunication until the next trip read (never, with trips off)."""
    async with opcua_gateway(opcua_toml(tmp_path)) as (gateway, server):
        await polled(gateway)
        drive = next(d for d in gateway.drives if d.node == 1)
        await wait_for(lambda: drive.snapshot.trips_at > -math.inf, "the trip history read")
        nodes = server._drives["hall", 1]
        by_name = {b.name: b for b in nodes.bindings}
        frequency, trips = (
            by_name["Monitoring/ConverterOutputFrequency"],
            by_name["Logbook/TripCount"],
        )
        # No await from here on: no real sample comes between these.
        server._watch(frequency.node, +1)  # a SCADA keeps watching the drive's frequency
        server._watch(trips.node, +1)
        online = drive.snapshot
        assert server._loop is not None
        now = server._loop.time()
        server.publish(drive.served)
        assert trips.quality(now) is Quality.GOOD

        def served(snapshot: DriveSnapshot) -> ServedDrive:
            return ServedDrive(
                snapshot,
                stale_after_s=drive.stale_after_s,
                trips_interval_s=drive.line.trips_interval_s,
            )

        server._watch(trips.node, -1)
        offline = served(dataclasses.replace(online, online=False, taken_at=online.taken_at + 1))
        # Its trips not read again: the same stamp.
        server.publish(offline)
        server._watch(trips.node, +1)
        trips.take(offline)  # asyncua's first read of a new monitored item
        assert trips.quality(now) is Quality.OFFLINE
        server.publish(served(dataclasses.replace(online, taken_at=online.taken_at + 2)))
        assert trips.quality(now) is Quality.GOOD
        assert trips.status(now) == ua.StatusCodes.Good


async def test_a_variable_is_taken_when_first_read_never_at_start(tmp_path: Path) -> None:
    """Issue 44: a value taken at start was kept by every variable nobody reads, and with
    it the start's served view of its drive (its snapshot and values: some 2 KiB a drive).
    Now nothing is taken until a read, a monitored item or a judgement asks; what a read
    is served is the drive's latest, as before."""
    async with (
        opcua_gateway(opcua_toml(tmp_path)) as (gateway, server),
        connected(server.url) as client,
    ):
        await polled(gateway)
        drive = gateway.drive("hall", 1)
        assert drive is not None
        nodes = server._drives["hall", 1]
        assert all(b.served is None and b.value is None for b in nodes.bindings)
        ns = await client.get_namespace_index(NAMESPACE)
        read = await client.get_node(
            ua.NodeId("hall/Drive1/Monitoring/ConverterOutputVoltage", ns)
        ).read_data_value()
        by_name = {b.name: b for b in nodes.bindings}
        voltage = by_name["Monitoring/ConverterOutputVoltage"]
        assert voltage.served is not None
        assert read.StatusCode.is_good()
        assert read.Value.Value == voltage.value is not None
        assert [b.name for b in nodes.bindings if b.served is not None] == [voltage.name]
        # Judged before it was ever taken (as the tick would): it takes the latest first.
        running = by_name["Monitoring/Running"]
        assert running.status(asyncio.get_running_loop().time()) == ua.StatusCodes.Good
        assert running.served is drive.served
        assert running.value is drive.snapshot.running is not None
