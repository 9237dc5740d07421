"""A broker that authenticates clients by certificate: mosquitto with ``require_certificate true``.

The gateway's ``[mqtt]`` and ``[sparkplug]`` sections take ``tls_cert`` and
``tls_key`` (AWS IoT Core, Azure IoT Hub, a Mosquitto of the plant's). The
broker here has a TLS listener that requires a client certificate signed by
its CA (tests/mqtt_tls.py makes a throw-away one), and a plain one for the
test's own subscriber (of the JSON topics: Sparkplug's payloads are
protobuf, which it would not read; the edge node's birth is its own word).
With the certificate, the gateway's state messages arrive and the Sparkplug
edge node is born; without one, or with one of another CA, the broker
refuses the connection (its log says why): the gateway never connects, says
so once at WARNING per northbound, and keeps trying (its back-off). Nothing
sleeps: each check waits for what the gateway or the broker says.
"""

from __future__ import annotations

import logging
from collections.abc import AsyncIterator
from pathlib import Path

import pytest
from cryptography.hazmat.primitives import serialization
from mqtt_broker import Broker, TlsListener, running_broker
from mqtt_tls import Identity, Pki, make_pki
from waiting import wait_for

from sj300_async.gateway import Gateway, GatewayConfigError, parse_config
from sj300_async.gateway.mqtt import MqttConfig
from sj300_async.gateway.mqtt._bridge import MqttBridge
from sj300_async.gateway.sparkplug import EdgeNode

from .conftest import SimLine, gateway_toml, running_gateway
from .test_gateway_mqtt import state_of, states, subscriber


@pytest.fixture
def pki(tmp_path: Path) -> Pki:
    return make_pki(tmp_path / "pki")


@pytest.fixture
async def broker(tmp_path: Path, pki: Pki) -> AsyncIterator[Broker]:
    listener = TlsListener(pki.ca, pki.broker.cert, pki.broker.key, require_certificate=True)
    async with running_broker(tmp_path, tls=listener) as b:
        yield b


def _tls_keys(pki: Pki, identity: Identity | None) -> str:
    keys = f'tls_ca = "{pki.ca}"\n'
    if identity is not None:
        keys += f'tls_cert = "{identity.cert}"\ntls_key = "{identity.key}"\n'
    return keys


def _toml(sim_line: SimLine, broker: Broker, pki: Pki, identity: Identity | None) -> str:
    tls = _tls_keys(pki, identity)
    extra = (
        f'[gateway]\nid = "gw1"\n[mqtt]\nurl = "{broker.tls_url}"\n{tls}'
        f'[sparkplug]\nurl = "{broker.tls_url}"\ngroup_id = "plant"\n{tls}'
    )
    return gateway_toml(sim_line.url, extra=extra)


def _broker_log(broker: Broker) -> str:
    """What mosquitto said (its log: the TLS handshake's verdict is there)."""
    return (broker.directory / "mosquitto.log").read_text(encoding="utf-8", errors="replace")


def _northbounds(gateway: Gateway) -> tuple[MqttBridge, EdgeNode]:
    bridge, node = gateway.northbounds["mqtt"], gateway.northbounds["sparkplug"]
    assert isinstance(bridge, MqttBridge)
    assert isinstance(node, EdgeNode)
    return bridge, node


async def test_the_broker_takes_the_gateway_s_client_certificate(
    sim_line: SimLine, broker: Broker, pki: Pki
) -> None:
    async with (
        subscriber(broker, "sj300/#", "sjtest/#") as sub,
        running_gateway(_toml(sim_line, broker, pki, pki.client)) as gateway,
    ):
        bridge, node = _northbounds(gateway)
        for number in range(1, 5):
            await sub.until(state_of(number), f"a state of node {number} over TLS")
        await wait_for(lambda: node.born, "the Sparkplug edge node born over TLS")
        assert bridge.connected
        assert (bridge.stats.connects, node.stats.connects) == (1, 1)
        assert states(sub, 1)[0].online
        assert node.stats.published["NBIRTH"] == 1
        log = _broker_log(broker)
        assert "as sj300-gw1 (" in log
        assert "as sj300-gw1-spb (" in log


@pytest.mark.parametrize("who", ["no certificate", "another CA's certificate"])
async def test_the_broker_refuses_a_gateway_without_a_certificate_it_trusts(
    sim_line: SimLine, broker: Broker, pki: Pki, who: str, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.DEBUG, logger="sj300_async.gateway")
    identity = None if who == "no certificate" else pki.stranger
    # mosquitto's words for each (OpenSSL's): what the broker saw, not only what we did.
    verdict = (
        "peer did not return a certificate" if identity is None else "certificate verify failed"
    )
    async with (
        subscriber(broker, "sj300/#", "sjtest/#") as sub,
        running_gateway(_toml(sim_line, broker, pki, identity)) as gateway,
    ):
        bridge, node = _northbounds(gateway)

        def still_unreachable(logger: str) -> bool:
            return any(
                r.name == logger and "still unreachable" in r.getMessage() for r in caplog.records
            )

        # Two failed attempts each: the first is said at WARNING, the next at DEBUG.
        await wait_for(lambda: still_unreachable("sj300_async.gateway.mqtt"), "a second attempt")
        await wait_for(
            lambda: still_unreachable("sj300_async.gateway.sparkplug"), "Sparkplug's second"
        )
        await wait_for(lambda: bridge.stats.samples["hall", 1] >= 2, "two polls")
        await sub.barrier()
        assert not bridge.connected
        assert not node.born
        assert (bridge.stats.connects, node.stats.connects) == (0, 0)
        assert not sub.where(lambda m: m.topic.startswith("sj300/gw1/"))
        assert not node.stats.published
        await wait_for(lambda: verdict in _broker_log(broker), f"the broker's {verdict!r}")
        assert "as sj300-gw1" not in _broker_log(broker)
    cannot = [
        r
        for r in caplog.records
        if r.levelno >= logging.WARNING and "cannot connect" in r.getMessage()
    ]
    assert len(cannot) == 2, [r.getMessage() for r in cannot]  # once per northbound
    assert all(broker.tls_url.removeprefix("mqtts://") in r.getMessage() for r in cannot)


def test_the_certificate_and_its_key_are_loaded_at_parse_time(pki: Pki, tmp_path: Path) -> None:
    """Paths relative to the file; one without the other, or a pair that does not match, is
    a configuration error, not a retry loop at connect time."""
    (tmp_path / "conf").mkdir()
    for name in ("gateway.crt", "gateway.key", "stranger.key", "ca.crt"):
        (tmp_path / "conf" / name).write_bytes((pki.ca.parent / name).read_bytes())
    # The gateway's key with a passphrase: refused at parse time, never prompted for (OpenSSL
    # would ask on the terminal, the event loop blocked at each connection attempt).
    key = serialization.load_pem_private_key((pki.ca.parent / "gateway.key").read_bytes(), None)
    (tmp_path / "conf" / "locked.key").write_bytes(
        key.private_bytes(
            serialization.Encoding.PEM,
            serialization.PrivateFormat.PKCS8,
            serialization.BestAvailableEncryption(b"secret"),
        )
    )
    line = '[[lines]]\nurl = "sim://"\nnodes = "1"\n'
    source = str(tmp_path / "conf" / "gateway.toml")

    def parse(keys: str) -> object:
        text = f'[gateway]\nid = "gw1"\n[mqtt]\nurl = "mqtt://b"\n{keys}{line}'
        return parse_config(text, source).northbounds["mqtt"]

    config = parse('tls_cert = "gateway.crt"\ntls_key = "gateway.key"\n')
    assert isinstance(config, MqttConfig)
    assert (config.tls, config.port) == (True, 8883)  # a client certificate means TLS
    assert config.tls_cert == tmp_path / "conf" / "gateway.crt"
    assert config.tls_key == tmp_path / "conf" / "gateway.key"
    for keys, error in [
        ('tls_cert = "gateway.crt"\n', "mqtt.tls_cert: tls_cert needs tls_key"),
        ('tls_key = "gateway.key"\n', "mqtt.tls_key: tls_key needs tls_cert"),
        ('tls_cert = "gateway.crt"\ntls_key = "nowhere.key"\n', "mqtt.tls_key: no such file"),
        (
            'tls_cert = "gateway.crt"\ntls_key = "stranger.key"\n',
            "mqtt.tls_cert: cannot load the certificate and key",
        ),
        ('tls_cert = "ca.crt"\ntls_key = "ca.crt"\n', "mqtt.tls_cert: cannot load"),
        ('tls_cert = "gateway.crt"\ntls_key = "locked.key"\n', "the key is encrypted"),
    ]:
        with pytest.raises(GatewayConfigError) as raised:
            parse(keys)
        assert error in str(raised.value), keys
        assert "\n" not in str(raised.value)
