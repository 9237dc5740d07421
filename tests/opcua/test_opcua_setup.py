"""Setting OPC UA up: the section, the flag, the certificate, trusted clients, asyncua's parts."""

from __future__ import annotations

import importlib.metadata
import inspect
import os
import stat
import textwrap
from pathlib import Path

import asyncua
import pytest
from asyncua import Server, ua
from asyncua.server.uaprocessor import UaProcessor
from asyncua.ua.uaerrors import UaError, UaStatusCodeError
from cryptography import x509
from waiting import wait_for

from sj300_async.gateway import GatewayConfigError, config_from_flags, parse_config
from sj300_async.gateway.opcua import DEFAULT_SECURITY, OpcuaConfig, _hooks

from .conftest import (
    NAMESPACE,
    PASSWORD,
    USER,
    Pair,
    connected,
    opcua_gateway,
    opcua_toml,
)

LINE = '[[lines]]\nname = "hall"\nurl = "sim://?nodes=1"\nnodes = "1"\n'


def _config(section: str, tmp_path: Path) -> OpcuaConfig:
    path = tmp_path / "gateway.toml"
    text = '[gateway]\nid = "gw1"\n[opcua]\n' + textwrap.dedent(section) + "\n" + LINE
    path.write_text(text)
    config = parse_config(text, str(path)).northbounds["opcua"]
    assert isinstance(config, OpcuaConfig)
    return config


def _error(section: str, tmp_path: Path) -> str:
    with pytest.raises(GatewayConfigError) as refused:
        _config(section, tmp_path)
    return str(refused.value)


def test_the_defaults_are_secure_and_relative_to_the_file(tmp_path: Path) -> None:
    config = _config('endpoint = "opc.tcp://0.0.0.0:4840"', tmp_path)
    assert config.security == DEFAULT_SECURITY == (
        "Basic256Sha256_SignAndEncrypt", "Basic256Sha256_Sign",
    )  # fmt: skip
    assert (config.endpoint.host, config.endpoint.port) == ("0.0.0.0", 4840)
    assert config.certificate == tmp_path / "opcua" / "cert.der"
    assert config.private_key == tmp_path / "opcua" / "key.pem"
    assert config.namespace == NAMESPACE
    assert config.users == ()
    assert config.url == "opc.tcp://0.0.0.0:4840"
    # The hardening's limits (docs/OPCUA.md, "Hardening").
    assert (config.max_connections, config.max_connections_per_address) == (32, 16)
    assert (config.max_unactivated_per_address, config.activate_within_s) == (4, 5.0)
    assert (config.login_burst, config.login_interval_s) == (5, 12.0)
    items = (config.max_monitored_items_per_session, config.max_monitored_items_per_address)
    assert items == (1000, 2000)


def test_the_nodeset_cache_is_the_user_s_unless_named_or_off(tmp_path: Path) -> None:
    endpoint = 'endpoint = "opc.tcp://h:1"\n'
    default = _config(endpoint, tmp_path).nodeset_cache
    assert default == Path(os.environ["XDG_CACHE_HOME"]) / "sj300-async"
    assert _config(endpoint + 'nodeset_cache = "cache"', tmp_path).nodeset_cache == (
        tmp_path / "cache"
    )
    assert _config(endpoint + 'nodeset_cache = ""', tmp_path).nodeset_cache is None
    message = _error(endpoint + "nodeset_cache = 3", tmp_path)
    assert "opcua.nodeset_cache: expected a string" in message


@pytest.mark.parametrize(
    ("section", "expected"),
    [
        ('endpoint = "tcp://host:4840"', "opcua.endpoint: expected opc.tcp://HOST:PORT"),
        ('endpoint = "opc.tcp://host"', "opcua.endpoint: expected opc.tcp://HOST:PORT"),
        ('endpoint = "opc.tcp://u:p@host:4840"', "carries no credentials"),
        ('endpoint = "opc.tcp://host:99999"', "opcua.endpoint: expected opc.tcp://HOST:PORT"),
        ("endpoint = 4840", "opcua.endpoint: expected a string"),
        ("", "opcua.endpoint: missing required key 'endpoint'"),
        (
            'endpoint = "opc.tcp://h:1"\nsecurity = ["Basic128"]',
            "opcua.security: unknown security mode 'Basic128'",
        ),
        ('endpoint = "opc.tcp://h:1"\nsecurity = []', "name at least one security mode"),
        ('endpoint = "opc.tcp://h:1"\nsecurity = ["None", "None"]', "named twice"),
        ('endpoint = "opc.tcp://h:1"\ntrusted_clients = "nowhere"', "no such directory"),
        ('endpoint = "opc.tcp://h:1"\nmax_connections = 0', "must be 1..1000"),
        (
            'endpoint = "opc.tcp://h:1"\nmax_connections = 8\nmax_connections_per_address = 9',
            "opcua.max_connections_per_address: must be 1..8, got 9",
        ),
        (
            'endpoint = "opc.tcp://h:1"\nmax_unactivated_per_address = "4"',
            "opcua.max_unactivated_per_address: expected an integer",
        ),
        ('endpoint = "opc.tcp://h:1"\nactivate_within_s = 0.1', "must be >= 0.5, got 0.1"),
        ('endpoint = "opc.tcp://h:1"\nlogin_interval_s = 7200', "must be 0.1..3600 s"),
        ('endpoint = "opc.tcp://h:1"\nlogin_burst = 0', "opcua.login_burst: must be 1..100"),
        (
            'endpoint = "opc.tcp://h:1"\nmax_monitored_items_per_address = 0',
            "opcua.max_monitored_items_per_address: must be 1..100000, got 0",
        ),
        ('endpoint = "opc.tcp://h:1"\ncolour = "red"', "opcua.colour: unknown key 'colour'"),
        (
            'endpoint = "opc.tcp://h:1"\n[[opcua.users]]\nname = "a"\npassword_hash = "x"',
            "opcua.users[0].password_hash: expected scrypt$N$R$P$SALT$HASH",
        ),
    ],
)
def test_a_bad_section_is_one_line_naming_the_key(
    tmp_path: Path, section: str, expected: str
) -> None:
    message = _error(section, tmp_path)
    assert expected in message
    assert message.startswith(str(tmp_path / "gateway.toml") + ":")
    assert "\n" not in message


def test_a_certificate_without_its_key_is_refused(tmp_path: Path) -> None:
    (tmp_path / "cert.der").write_bytes(b"x")
    message = _error(
        'endpoint = "opc.tcp://h:1"\ncertificate = "cert.der"\nprivate_key = "key.pem"', tmp_path
    )
    assert "opcua.private_key:" in message
    assert "both exist or neither" in message


def test_the_flag_sets_the_endpoint() -> None:
    config = config_from_flags(
        url="sim://?nodes=1",
        nodes="1",
        protocol=None,
        northbounds={"opcua": "opc.tcp://127.0.0.1:4841"},
    ).northbounds["opcua"]
    assert isinstance(config, OpcuaConfig)
    assert config.endpoint.port == 4841


async def test_the_certificate_is_generated_once_then_kept(
    tmp_path: Path, client_pair: Pair
) -> None:
    text = opcua_toml(tmp_path)
    async with opcua_gateway(text) as (_, server):
        first = server.certificate
        assert first is not None
        assert first.generated
        assert first.application_uri == NAMESPACE
        assert "generated" in str(server.announce())
        assert first.thumbprint in str(server.announce())
        # The client sees it and opens an encrypted channel with it.
        async with connected(server.url, pair=client_pair, user=USER, password=PASSWORD) as client:
            endpoints = await client.get_endpoints()
            der = {endpoint.ServerCertificate for endpoint in endpoints}
            assert der == {first.certificate.read_bytes()}
            uris = x509.load_der_x509_certificate(der.pop()).extensions.get_extension_for_class(
                x509.SubjectAlternativeName
            )
            assert NAMESPACE in uris.value.get_values_for_type(x509.UniformResourceIdentifier)
    key_mode = stat.S_IMODE(first.private_key.stat().st_mode)
    assert key_mode == 0o600
    assert stat.S_IMODE(first.private_key.parent.stat().st_mode) == 0o700
    async with opcua_gateway(text) as (_, server):
        again = server.certificate
        assert again is not None
        assert not again.generated
        assert again.thumbprint == first.thumbprint


async def test_only_trusted_client_certificates_open_a_session(
    tmp_path: Path, client_pair: Pair, other_pair: Pair
) -> None:
    trusted = tmp_path / "trusted"
    trusted.mkdir()
    (trusted / "client.der").write_bytes(client_pair.certificate.read_bytes())
    (trusted / "notes.txt").write_text("not a certificate")
    text = opcua_toml(tmp_path, opcua_extra=f'trusted_clients = "{trusted}"')
    async with opcua_gateway(text) as (_, server):
        async with connected(server.url, pair=client_pair, user=USER, password=PASSWORD) as ok:
            assert await ok.get_namespace_index(NAMESPACE) > 0
        # Refused when its channel opens: the connection is closed before any session.
        with pytest.raises((UaError, ConnectionError)):
            async with connected(server.url, pair=other_pair, user=USER, password=PASSWORD):
                pass
        assert server.untrusted >= 1
        assert server.session_count == 0


async def test_an_unsecured_only_server_reads_but_never_writes(
    tmp_path: Path, client_pair: Pair
) -> None:
    text = opcua_toml(tmp_path, security='["None"]')
    async with opcua_gateway(text) as (gateway, server):
        await wait_for(lambda: all(d.snapshot.available for d in gateway.drives), "samples")
        assert server.announce() is not None
        assert "(None)" in str(server.announce())
        async with connected(server.url, user=USER, password=PASSWORD) as client:
            ns = await client.get_namespace_index(NAMESPACE)
            drive = client.get_node(ua.NodeId("hall/Drive1", ns))
            assert await client.get_node(ua.NodeId("hall/Drive1/Online", ns)).read_value()
            with pytest.raises(UaStatusCodeError) as refused:
                await drive.call_method(f"{ns}:Stop")
            assert ua.StatusCode(refused.value.code).name == "BadSecurityModeInsufficient"
        # Only the endpoint named: no Basic256Sha256 endpoint is offered.
        async with connected(server.url) as client:
            modes = {endpoint.SecurityMode for endpoint in await client.get_endpoints()}
            assert modes == {ua.MessageSecurityMode.None_}


async def test_the_default_server_offers_no_unsecured_endpoint(tmp_path: Path) -> None:
    text = opcua_toml(tmp_path, security='["Basic256Sha256_SignAndEncrypt"]')
    async with opcua_gateway(text) as (_, server):
        with pytest.raises(UaStatusCodeError) as refused:
            async with connected(server.url):  # SecurityPolicy None: not offered, no session
                pass
        assert ua.StatusCode(refused.value.code).name == "BadSecurityPolicyRejected"
        probe = asyncua.Client(server.url)
        endpoints = await probe.connect_and_get_server_endpoints()
        assert {e.SecurityMode for e in endpoints} == {ua.MessageSecurityMode.SignAndEncrypt}


def test_asyncua_still_has_what_the_hooks_reach_past_its_api() -> None:
    """gateway/opcua/_hooks.py depends on these; an asyncua release that moves them fails here."""
    server = Server()
    assert hasattr(server, "_policies")
    iserver = server.iserver
    assert callable(iserver.unregister_external_session)
    assert hasattr(iserver, "attribute_service")
    assert hasattr(iserver, "_external_sessions")
    assert hasattr(iserver, "max_connections")
    from asyncua.crypto.security_policies import SecurityPolicyFactory

    factory = SecurityPolicyFactory(None, ua.MessageSecurityMode.Sign)
    assert hasattr(factory, "permission_ruleset")
    assert factory.mode == ua.MessageSecurityMode.Sign
    assert hasattr(iserver, "endpoints")
    assert callable(iserver.decrypt_user_token)
    assert callable(iserver.lookup_external_session)


def test_asyncua_is_a_release_the_request_guards_were_tested_with() -> None:
    """guard_requests wraps asyncua's connection and request processing: an asyncua of
    another release is guarded only if those have the same shape; moving to one means
    running these tests against it and naming it in TESTED_ASYNCUA."""
    assert importlib.metadata.version("asyncua") in _hooks.TESTED_ASYNCUA
    for (owner, name), parameters in _hooks._WRAPPED.items():
        assert list(inspect.signature(getattr(owner, name)).parameters) == parameters, name


async def test_an_asyncua_processing_otherwise_falls_back_to_checking_passwords_itself(
    tmp_path: Path,
    client_pair: Pair,
    monkeypatch: pytest.MonkeyPatch,
    caplog: pytest.LogCaptureFixture,
) -> None:
    """The public path: no request guard, and the user manager checks each password on the
    loop within the budget every client shares (bounded, counted)."""
    wrapped = dict(_hooks._WRAPPED)
    wrapped[(UaProcessor, "_process_message")] = ["self", "moved"]
    monkeypatch.setattr(_hooks, "_WRAPPED", wrapped)
    async with opcua_gateway(opcua_toml(tmp_path)) as (_, server):
        assert not server._defences.guarded
        assert "differs from" in caplog.text
        async with connected(server.url, pair=client_pair, user=USER, password=PASSWORD) as ok:
            assert await ok.get_namespace_index(NAMESPACE) > 0
        with pytest.raises(UaStatusCodeError):
            async with connected(server.url, pair=client_pair, user=USER, password="wrong"):
                pass
        assert server._users.refusals["password"] == 1
        assert server._defences.checks.checked == 0  # none went through the guarded path
