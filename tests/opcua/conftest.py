"""Fixtures of the OPC UA tests: a gateway's configuration, certificates, asyncua clients.

A gateway is entered and left in the test's own task (no async fixture
yields one): asyncua's server tasks belong to the loop that started them.
The server's certificate and a client's are made once per test session
(RSA key generation is the slow part); each test still gets its own copy
in its own directory.
"""

from __future__ import annotations

import contextlib
import shutil
import textwrap
from collections.abc import AsyncIterator
from dataclasses import dataclass
from pathlib import Path

import pytest
from asyncua import Client, ua
from asyncua.crypto import cert_gen
from cryptography import x509
from cryptography.hazmat.primitives import serialization
from cryptography.x509.oid import ExtendedKeyUsageOID
from waiting import wait_for

from sj300_async.gateway import Gateway, hash_password, parse_config
from sj300_async.gateway.opcua._server import OpcuaServer
from sj300_async.simulator import serve_tcp
from sj300_async.simulator.sj300 import SimulatedBus

# Defined beside the attacks, which run as a script where this module is not importable;
# here for the tests that import them from conftest.
from .opcua_attacker import CLIENT_URI as CLIENT_URI
from .opcua_attacker import USER as USER
from .opcua_attacker import from_address as from_address
from .opcua_attacker import unsecured_channel as unsecured_channel

#: The password of :data:`USER`, the user every secure test logs in as.
PASSWORD = "s3cret-pass"
NAMESPACE = "urn:sj300-async:gw1"
_HASH = hash_password(PASSWORD)


@dataclass(frozen=True)
class Pair:
    certificate: Path
    key: Path


def make_pair(directory: Path, name: str, uri: str) -> Pair:
    """A self-signed client certificate (DER) for *uri* and its key (PEM)."""
    key = cert_gen.generate_private_key()
    certificate = cert_gen.generate_self_signed_app_certificate(
        key,
        name,
        {},
        [x509.UniformResourceIdentifier(uri), x509.DNSName("localhost")],
        [ExtendedKeyUsageOID.CLIENT_AUTH],
        days=30,
    )
    pair = Pair(directory / f"{name}-cert.der", directory / f"{name}-key.pem")
    pair.certificate.write_bytes(certificate.public_bytes(serialization.Encoding.DER))
    pair.key.write_bytes(cert_gen.dump_private_key_as_pem(key))
    return pair


@pytest.fixture(scope="session")
def _pairs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Pair]:
    base = tmp_path_factory.mktemp("opcua-pki")
    return {
        "client": make_pair(base, "client", CLIENT_URI),
        "other": make_pair(base, "other", "urn:sj300-async:other-client"),
    }


@pytest.fixture
def client_pair(_pairs: dict[str, Pair], tmp_path: Path) -> Pair:
    """The test client's certificate and key (DER, PEM), in this test's directory."""
    source = _pairs["client"]
    pair = Pair(tmp_path / "client-cert.der", tmp_path / "client-key.pem")
    shutil.copy(source.certificate, pair.certificate)
    shutil.copy(source.key, pair.key)
    return pair


@pytest.fixture
def other_pair(_pairs: dict[str, Pair]) -> Pair:
    """A second client certificate (not trusted where a test trusts only the first)."""
    return _pairs["other"]


def opcua_toml(
    directory: Path,
    *,
    url: str = "sim://?nodes=1-4",
    security: str = '["Basic256Sha256_SignAndEncrypt", "Basic256Sha256_Sign", "None"]',
    opcua_extra: str = "",
    line_extra: str = "",
    gateway_extra: str = "",
    users: bool = True,
) -> str:
    """A gateway ``gw1`` with line ``hall`` (nodes 1-4 at 0.1 s) and OPC UA on a free port.

    Drives 1 and 2 are granted control and F002; the server's certificate is generated
    in *directory* at start.
    """
    user = f'[[opcua.users]]\nname = "{USER}"\npassword_hash = "{_HASH}"\n' if users else ""
    return (
        textwrap.dedent(
            f"""
            [gateway]
            id = "gw1"
            {gateway_extra}
            [opcua]
            endpoint = "opc.tcp://127.0.0.1:0"
            security = {security}
            certificate = "{directory / "server" / "cert.der"}"
            private_key = "{directory / "server" / "key.pem"}"
            {opcua_extra}
            """
        )
        + user
        + textwrap.dedent(
            f"""
            [[lines]]
            name = "hall"
            url = "{url}"
            nodes = "1-4"
            interval_s = 0.1
            parameters = ["A004", "F002"]
            {line_extra}
            [[lines.writes]]
            nodes = "1-2"
            control = true
            parameters = ["F002"]
            """
        )
    )


@contextlib.asynccontextmanager
async def opcua_gateway(
    text: str, *, tune_collector: bool = False
) -> AsyncIterator[tuple[Gateway, OpcuaServer]]:
    """A gateway with an OPC UA northbound; *tune_collector* as ``sj300 gateway`` runs it."""
    config = parse_config(text, "test.toml")
    async with Gateway(config, tune_collector=tune_collector) as gateway:
        server = gateway.northbounds["opcua"]
        assert isinstance(server, OpcuaServer)
        yield gateway, server


@contextlib.asynccontextmanager
async def connected(
    url: str,
    *,
    pair: Pair | None = None,
    mode: str = "SignAndEncrypt",
    user: str | None = None,
    password: str | None = None,
) -> AsyncIterator[Client]:
    """An asyncua client session (anonymous and unsecured unless told otherwise)."""
    client = Client(url, timeout=10)
    client.application_uri = CLIENT_URI
    if pair is not None:
        await client.set_security_string(f"Basic256Sha256,{mode},{pair.certificate},{pair.key}")
    if user is not None:
        client.set_user(user)
        client.set_password(password or "")
    async with client:
        yield client


def node(client: Client, namespace: int, path: str) -> object:
    """The client's node of a drive variable by its path (``hall/Drive1/Monitoring/State``)."""
    return client.get_node(ua.NodeId(path, namespace))


async def polled(gateway: Gateway) -> None:
    """Every drive heard from (a drive not heard yet refuses runs like an offline one)."""
    await wait_for(lambda: all(d.snapshot.available for d in gateway.drives), "first samples")


@contextlib.asynccontextmanager
async def tcp_line() -> AsyncIterator[tuple[SimulatedBus, str]]:
    """Drives 1..4 simulated behind TCP (``url``): the test reaches the simulated line."""
    sim = SimulatedBus(range(1, 5))
    server = await serve_tcp(sim)
    async with server:
        yield sim, f"tcp://127.0.0.1:{server.port}"
