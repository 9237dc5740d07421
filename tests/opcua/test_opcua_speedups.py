"""The speed patches' gate (gateway/opcua/_speedups.py): switched off, asyncua is left as it is.

With ``SJ300_OPCUA_SPEEDUPS=0`` (or an asyncua release the patches were not
tested with) a gateway serving a subscription must replace no asyncua class
attribute and no function of its modules but guard_requests' wrapping of the
connection and request processing (the hardening, always on: _hooks.py), and
make its values plain DataValues. A child process shows it: the switch is
read once, at import, and this process's asyncua may be patched already.
"""

from __future__ import annotations

import importlib.metadata
import logging
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
from asyncua import ua

from sj300_async.gateway.opcua import _speedups
from sj300_async.gateway.opcua._operations import _COUNTED

_CHILD = textwrap.dedent(
    """
    import asyncio, inspect, logging, sys
    from pathlib import Path

    logging.basicConfig(level=logging.INFO)

    import asyncua.server.binary_server_asyncio, asyncua.server.monitored_item_service
    import asyncua.server.uaprocessor, asyncua.server.address_space
    import asyncua.server.subscription_service, asyncua.server.internal_subscription
    import asyncua.ua.ua_binary
    from asyncua import Client, ua

    def attributes(modules=None):
        # Every function of the asyncua modules and every method of their classes.
        seen = {}
        for name, module in list(sys.modules.items()):
            if not name.startswith("asyncua") or module is None:
                continue
            if modules is not None and name not in modules:
                continue
            for key, value in list(vars(module).items()):
                if callable(value):
                    seen[(name, key)] = value
                if inspect.isclass(value) and value.__module__ == name:
                    for attr, member in list(vars(value).items()):
                        if callable(member) or isinstance(
                            member, (classmethod, staticmethod, property)
                        ):
                            seen[(name, f"{key}.{attr}")] = member
        return seen

    before = attributes()

    from sj300_async.gateway import Gateway, parse_config
    from sj300_async.gateway.opcua import _speedups
    from sj300_async.gateway.opcua._values import drive_datavalue

    assert not _speedups.ENABLED, _speedups.OFF_BECAUSE
    directory = Path(sys.argv[1])
    text = f'''
    [gateway]
    id = "gw1"
    [opcua]
    endpoint = "opc.tcp://127.0.0.1:0"
    security = ["None"]
    certificate = "{directory / 'cert.der'}"
    private_key = "{directory / 'key.pem'}"
    [[lines]]
    name = "hall"
    url = "sim://?nodes=1"
    nodes = "1"
    interval_s = 0.1
    '''

    class Seen:
        def __init__(self):
            self.values = []

        def datachange_notification(self, node, value, data):
            self.values.append(data.monitored_item.Value)

    async def main():
        async with Gateway(parse_config(text, "child.toml")) as gateway:
            server = gateway.northbounds["opcua"]
            async with Client(server.url, timeout=10) as client:
                ns = await client.get_namespace_index("urn:sj300-async:gw1")
                seen = Seen()
                subscription = await client.create_subscription(100, seen)
                await subscription.subscribe_data_change(
                    [
                        client.get_node(ua.NodeId(f"hall/Drive1/{path}", ns))
                        for path in ("Monitoring/ConverterOutputFrequency", "Logbook/TripCount")
                    ]
                )
                for _ in range(100):
                    if server.pushed and len(seen.values) >= 2:
                        break
                    await asyncio.sleep(0.05)
                assert seen.values, "no notification"
                (binding, *_) = server._drives["hall", 1].bindings
                assert type(drive_datavalue(binding, 0)) is ua.DataValue
                assert server.session_count == 1
                # Every node made at start, in asyncua's own table (no _lazy): a dict, or
                # its shelf's mapping where the standard nodeset is cached (_nodeset).
                assert server.lazy_nodes is None
                table = type(server.address_space._nodes).__name__
                assert table in ("dict", "LazyLoadingDict"), table

    asyncio.run(main())
    after = attributes({name for name, _ in before})
    for key in sorted(set(before) | set(after), key=str):
        if key in before and key in after and before[key] is after[key]:
            continue
        print("changed", key[0], key[1])
    """
)
#: What the hardening replaces, always (_hooks.guard_requests, once per process).
_GUARDED = {
    "asyncua.server.binary_server_asyncio OPCUAProtocol.connection_made",
    "asyncua.server.binary_server_asyncio OPCUAProtocol.connection_lost",
    "asyncua.server.binary_server_asyncio OPCUAProtocol.data_received",
    "asyncua.server.binary_server_asyncio OPCUAProtocol._process_one_msg",
    "asyncua.server.uaprocessor UaProcessor._process_message",
    # _operations.limit_operations: each service's operations per request.
    *(f"asyncua.server.internal_session InternalSession.{name}" for name in _COUNTED),
}


def test_switched_off_no_asyncua_class_or_function_is_replaced_but_the_guards(
    tmp_path: Path,
) -> None:
    env = {**os.environ, _speedups.SWITCH: "0"}
    done = subprocess.run(
        [sys.executable, "-c", _CHILD, str(tmp_path)],
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert done.returncode == 0, done.stderr[-3000:]
    changed = {
        line.removeprefix("changed ")
        for line in done.stdout.splitlines()
        if line.startswith("changed")
    }
    assert changed <= _GUARDED, changed - _GUARDED
    assert "speed patches off (SJ300_OPCUA_SPEEDUPS=0)" in done.stderr


def test_the_speed_patches_are_on_for_a_tested_release_unless_switched_off() -> None:
    """The releases the patches were tested with are the one installed (moving to another
    means running tests/opcua against it and naming it in TESTED_ASYNCUA)."""
    assert importlib.metadata.version("asyncua") in _speedups.TESTED_ASYNCUA
    switched_off = os.environ.get(_speedups.SWITCH, "").lower() in ("0", "false", "no", "off")
    assert _speedups.ENABLED is not switched_off
    assert (_speedups.ServedDataValue is _speedups.FrozenDataValue) is _speedups.ENABLED


def test_off_the_reason_is_logged_once_and_nothing_is_patched(
    monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    monkeypatch.setattr(_speedups, "ENABLED", False)
    monkeypatch.setattr(_speedups, "OFF_BECAUSE", "asyncua 9.9.9 is not a release they were")
    monkeypatch.setattr(_speedups, "_told", False)
    monkeypatch.setattr(_speedups, "_copying", None)
    monkeypatch.setattr(_speedups, "_serializers", None)
    monkeypatch.setattr(_speedups, "_sharing", None)
    with caplog.at_level(logging.INFO, logger="sj300_async.gateway.opcua"):
        assert not _speedups.install()
        assert not _speedups.install()
    (record,) = caplog.records
    assert record.levelno == logging.WARNING
    assert "speed patches off (asyncua 9.9.9" in record.getMessage()
    assert _speedups._copying is None
    assert _speedups._serializers is None
    assert not _speedups.push_frozen(None, ua.NodeId(1), None)  # type: ignore[arg-type]
