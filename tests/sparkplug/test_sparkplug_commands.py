"""DCMD and NCMD as a host sends them (encoded by Eclipse Tahu, published by mosquitto_pub).

Writes go through the gateway's controller: without the lease a run is
refused and the refusal comes back in the device's ``Control/Last
Refusal``; with it the drive runs. Bad input changes nothing and is
counted by reason, and audited where it names a drive.
"""

from __future__ import annotations

from collections.abc import Awaitable, Callable
from typing import Any

from mqtt_broker import Broker
from waiting import wait_for

from sj300_async.gateway import Gateway
from sj300_async.gateway.sparkplug import EdgeNode

from .conftest import SimLine, drive, edge, running_gateway, spb_toml
from .host import Codec, Host, host
from .test_sparkplug_lifecycle import births, current, names, seqs_follow


def alias(h: Host, device: str, name: str) -> int:
    value: int = names(births(h, device)[-1])[name]["alias"]
    return value


def metric(h: Host, device: str, name: str, kind: str, value: Any) -> dict[str, Any]:
    """A DCMD metric as the specification has a host send it: by alias, with its type."""
    return {"alias": alias(h, device, name), "type": kind, "value": value}


async def bad_inputs_reach(node: EdgeNode, total: int, what: str) -> None:
    await wait_for(lambda: sum(node.stats.bad_input.values()) == total, what)


def sparkplug_audit(gateway: Gateway) -> list[dict[str, object]]:
    return [entry for entry in gateway.audit.recent if entry["client"] == "sparkplug"]


async def test_a_dcmd_runs_the_drive_only_with_the_lease(
    sim_line: SimLine, broker: Broker, tahu: Codec
) -> None:
    async with host(broker, tahu) as h:
        async with running_gateway(spb_toml(sim_line.url, broker)) as gateway:
            await h.until(lambda m: m.kind == "DBIRTH", "a birth per drive", count=4)
            one = drive(gateway, 1)
            await h.command("DCMD", [metric(h, "hall-1", "Direction", "String", "forward")],
                            "hall-1")  # fmt: skip
            await h.until(lambda m: current(h, "hall-1")["Control/Refusals"] == 1, "the refusal")
            assert "no_lease" in current(h, "hall-1")["Control/Last Refusal"]
            assert not one.snapshot.running
            assert sparkplug_audit(gateway)[-1]["result"] == "refused"
            # A parameter (the maximum frequency, while stopped: an SJ300 refuses it while
            # running), named by name this time: a host may, though the alias is the rule.
            await h.command("DCMD", [
                metric(h, "hall-1", "Control/Lease", "Boolean", True),
                {"name": "Parameters/A004", "type": "Double", "value": 60.0},
            ], "hall-1")  # fmt: skip
            await h.until(lambda m: current(h, "hall-1")["Parameters/A004"] == 60.0, "A004 set")
            await h.command("DCMD", [
                metric(h, "hall-1", "Frequency Command", "Double", 25.0),
                metric(h, "hall-1", "Direction", "String", "forward"),
            ], "hall-1")  # fmt: skip
            await h.until(lambda m: current(h, "hall-1")["Running"] is True, "the drive running")
            values = current(h, "hall-1")
            assert (values["Frequency Command"], values["Control/Lease"]) == (25.0, True)
            assert one.lease.holder == "sparkplug"
            await h.command("DCMD", [metric(h, "hall-1", "Control/Stop", "Boolean", True)],
                            "hall-1")  # fmt: skip
            await h.until(lambda m: current(h, "hall-1")["Direction"] == "stop", "the stop")
            stats = edge(gateway).stats
            assert (stats.writes, stats.refused) == (5, 1)
            assert [(entry["what"], entry["result"]) for entry in sparkplug_audit(gateway)] == [
                ("command", "refused"), ("heartbeat", "ok"), ("parameter A004", "ok"),
                ("set frequency (Hz)", "ok"), ("command", "ok"), ("command", "ok"),
            ]  # fmt: skip
        # The session ends with the gateway: the connection-scoped lease lapses (audited).
        last = sparkplug_audit(gateway)[-1]
        assert (last["what"], last["new"]) == ("lease lapsed: stop", "confirmed stopped")
    seqs_follow(h.messages)


async def test_bad_input_changes_nothing_and_is_counted(
    sim_line: SimLine, broker: Broker, tahu: Codec
) -> None:
    async with host(broker, tahu) as h:
        # A retained command, there before the gateway: the broker hands it over at the
        # subscribe, flagged retained (stored, sent by nobody now): never carried out.
        await h.command("DCMD", [{"name": "Direction", "type": "String", "value": "forward"}],
                        "hall-1", retain=True)  # fmt: skip
        async with running_gateway(spb_toml(sim_line.url, broker)) as gateway:
            node = edge(gateway)
            await wait_for(lambda: node.stats.bad_input["retained"] == 1, "the retained one")
            await h.until(lambda m: m.kind == "DBIRTH", "a birth per drive", count=4)
            one, three = drive(gateway, 1), drive(gateway, 3)
            lease = metric(h, "hall-1", "Control/Lease", "Boolean", True)
            await h.command("DCMD", [lease], "hall-1")
            await wait_for(lambda: one.lease.holder == "sparkplug", "the lease")
            set_hz = one.snapshot.set_frequency_hz
            sent: list[tuple[str, Callable[[], Awaitable[None]]]] = [
                ("malformed", lambda: h.raw("DCMD", b"\xff\x01 no protobuf", "hall-1")),
                ("unknown_metric", lambda: h.command(
                    "DCMD", [{"alias": 9_999_999, "type": "Double", "value": 1.0}], "hall-1")),
                ("wrong_type", lambda: h.command(
                    "DCMD", [metric(h, "hall-1", "Frequency Command", "String", "10")], "hall-1")),
                ("wrong_type", lambda: h.command(
                    "DCMD", [metric(h, "hall-1", "Direction", "Double", 1.0)], "hall-1")),
                ("unknown_device", lambda: h.command(
                    "DCMD", [metric(h, "hall-1", "Direction", "String", "forward")], "hall-9")),
                ("malformed", lambda: h.raw("NCMD", b"\x0a\xff")),
                ("unknown_metric", lambda: h.command(
                    "NCMD", [{"name": "Node Control/Reboot", "type": "Boolean", "value": True}])),
            ]  # fmt: skip
            for count, (reason, send) in enumerate(sent, start=2):
                before = node.stats.bad_input[reason]
                await send()
                await bad_inputs_reach(node, count, f"bad input {count} ({reason}) counted")
                assert node.stats.bad_input[reason] == before + 1
            # A read-only drive's metric, and a drive the poller holds offline.
            await h.command("DCMD", [metric(h, "hall-3", "Output Frequency", "Double", 5.0)],
                            "hall-3")  # fmt: skip
            sim_line.sim.faults.silence(2)
            await h.until(lambda m: m.kind == "DDEATH", "hall-2 dead")
            await h.command("DCMD", [metric(h, "hall-2", "Control/Lease", "Boolean", True),
                                     metric(h, "hall-2", "Frequency Command", "Double", 12.0)],
                            "hall-2")  # fmt: skip
            await wait_for(lambda: node.stats.bad_input["offline"] == 1, "the offline drive")
            assert not one.snapshot.running
            assert not three.snapshot.running
            assert one.snapshot.set_frequency_hz == set_hz
            assert node.stats.writes == 2  # the two leases, nothing else
            refused = [e for e in sparkplug_audit(gateway) if e["result"] == "refused"]
            # Each refusal that names a drive is audited: not the unknown device's, nor
            # the node's own commands.
            assert len(refused) == 7, refused
    assert node.stats.rebirths == 0


async def test_a_stop_waits_behind_no_command_and_a_flood_is_one_audit_line(
    sim_line: SimLine, broker: Broker, tahu: Codec
) -> None:
    async with host(broker, tahu) as h, running_gateway(spb_toml(sim_line.url, broker)) as gateway:
        await h.until(lambda m: m.kind == "DBIRTH", "a birth per drive", count=4)
        node = edge(gateway)
        hz = [metric(h, "hall-1", "Frequency Command", "Double", 10.0 + n) for n in range(30)]
        stop = metric(h, "hall-1", "Control/Stop", "Boolean", True)
        lease = metric(h, "hall-1", "Control/Lease", "Boolean", True)
        await h.command("DCMD", [lease, *hz, stop], "hall-1")
        await wait_for(
            lambda: any(e["what"] == "command" and e["new"] == "stop"
                        for e in sparkplug_audit(gateway)), "the stop carried out",
        )  # fmt: skip
        audit = sparkplug_audit(gateway)
        # Each of the 32 audited once: the stop carried out; what waited before it
        # dropped, what found the queue full refused busy; nothing else.
        assert len(audit) == 32
        stops = [e for e in audit if e["what"] == "command"]
        assert [(e["new"], e["result"]) for e in stops] == [("stop", "ok")]
        assert {e.get("reason") for e in audit if e["result"] == "refused"} == {"busy"}
        assert any(e.get("detail") == "dropped: a stop came after it" for e in audit)
        # 100 metrics in one DCMD: 64 judged, the rest refused in one audit line.
        before = len(sparkplug_audit(gateway))
        await h.command("DCMD", [metric(h, "hall-1", "Output Frequency", "Double", 1.0)] * 100,
                        "hall-1")  # fmt: skip
        await wait_for(lambda: node.stats.bad_input["too_many"] == 36, "the excess counted")
        await wait_for(lambda: len(sparkplug_audit(gateway)) == before + 65, "65 audit lines")
