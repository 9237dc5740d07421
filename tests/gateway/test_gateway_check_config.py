"""``sj300 gateway --check-config FILE``: a start's refusals, found without starting.

Each refusal is compared with what ``sj300 gateway --config FILE`` prints for
the same file: the same line, the same exit status. The configurations the
parser's tests refuse are all checked that way; then what only a start
finds (a port in use, an address not on this host, a certificate that does
not load, an audit log that cannot be written), and a good file's summary,
with nothing left behind: no port held, no file made.
"""

from __future__ import annotations

import asyncio
import socket
import textwrap
from collections.abc import Iterator
from pathlib import Path

import pytest
from cli.clirun import sj300

from sj300_async.cli import main

from .test_gateway_config import REFUSALS

#: A line the checks never open (a start would: the simulator, in the process).
_LINE = """
[[lines]]
name = "l1"
url = "sim://?nodes=1-2"
nodes = "1-2"
"""


def _run(capsys: pytest.CaptureFixture[str], *args: str) -> tuple[int, str, str]:
    status = main(["gateway", *args])
    out, err = capsys.readouterr()
    return status, out, err


def _same_as_a_start(capsys: pytest.CaptureFixture[str], path: str) -> str:
    """Check *path*, start with it, and return the one line both printed (exit 2)."""
    checked = _run(capsys, "--check-config", path)
    started = _run(capsys, "--config", path)
    assert checked[0] == started[0] == 2, (checked, started)
    assert checked[1] == started[1] == ""
    assert checked[2] == started[2], (checked, started)
    lines = checked[2].splitlines()
    assert len(lines) == 1, lines
    assert lines[0].startswith("sj300 gateway: error: "), lines
    return lines[0].removeprefix("sj300 gateway: error: ")


@pytest.fixture
def here(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """*tmp_path* as the working directory (the refusals name ``gateway.toml``)."""
    monkeypatch.chdir(tmp_path)
    return tmp_path


@pytest.fixture
def listening() -> Iterator[int]:
    """A port some other program listens on."""
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        yield taken.getsockname()[1]


@pytest.mark.parametrize(("text", "message"), REFUSALS)
def test_every_refused_file_gets_the_start_s_line(
    here: Path, capsys: pytest.CaptureFixture[str], text: str, message: str
) -> None:
    (here / "gateway.toml").write_text(text, encoding="utf-8")
    assert _same_as_a_start(capsys, "gateway.toml") == message


def test_a_port_in_use(here: Path, capsys: pytest.CaptureFixture[str], listening: int) -> None:
    (here / "gateway.toml").write_text(f'[modbus]\nlisten = "127.0.0.1:{listening}"\n' + _LINE)
    line = _same_as_a_start(capsys, "gateway.toml")
    assert line == f"modbus: cannot listen on 127.0.0.1:{listening}: Address already in use"


def test_a_port_in_use_is_left_out_beside_the_running_gateway(
    here: Path, capsys: pytest.CaptureFixture[str], listening: int
) -> None:
    (here / "gateway.toml").write_text(f'[http]\nlisten = "127.0.0.1:{listening}"\n' + _LINE)
    status, out, err = _run(capsys, "--check-config", "gateway.toml", "--no-port-check")
    assert (status, err) == (0, "")
    assert f"http: listens on 127.0.0.1:{listening}" in out


def test_an_address_not_on_this_host(here: Path, capsys: pytest.CaptureFixture[str]) -> None:
    # 192.0.2.1 is TEST-NET-1 (RFC 5737): on no interface here.
    (here / "gateway.toml").write_text('[http]\nlisten = "192.0.2.1:8080"\n' + _LINE)
    line = _same_as_a_start(capsys, "gateway.toml")
    assert line == "http: cannot listen on 192.0.2.1:8080: Cannot assign requested address"


def test_a_host_name_that_does_not_resolve(here: Path, capsys: pytest.CaptureFixture[str]) -> None:
    (here / "gateway.toml").write_text('[modbus]\nlisten = "no-such-host.invalid:1502"\n' + _LINE)
    line = _same_as_a_start(capsys, "gateway.toml")
    assert line.startswith("modbus: cannot listen on no-such-host.invalid:1502: cannot resolve")


def test_a_certificate_that_does_not_load(here: Path, capsys: pytest.CaptureFixture[str]) -> None:
    (here / "opcua").mkdir()
    (here / "opcua" / "cert.der").write_bytes(b"not a certificate")
    (here / "opcua" / "key.pem").write_bytes(b"not a key")
    (here / "gateway.toml").write_text('[opcua]\nendpoint = "opc.tcp://127.0.0.1:0"\n' + _LINE)
    line = _same_as_a_start(capsys, "gateway.toml")
    assert line.startswith("opcua: cannot use the certificate opcua/cert.der: "), line


@pytest.mark.parametrize(
    ("certificate", "error"),
    [
        ("opcua/cert.der", "[Errno 17] File exists: 'opcua'"),
        ("opcua/deeper/cert.der", "[Errno 20] Not a directory: 'opcua/deeper'"),
    ],
)
def test_a_file_where_the_certificate_s_directory_would_be(
    here: Path, capsys: pytest.CaptureFixture[str], certificate: str, error: str
) -> None:
    (here / "opcua").write_text("a file, not a directory")
    text = f'[opcua]\nendpoint = "opc.tcp://127.0.0.1:0"\ncertificate = "{certificate}"\n'
    (here / "gateway.toml").write_text(text + 'private_key = "key.pem"\n' + _LINE)
    line = _same_as_a_start(capsys, "gateway.toml")
    assert line == f"opcua: cannot use the certificate {certificate}: {error}"


def test_an_audit_log_that_cannot_be_written(
    here: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    text = '[gateway]\naudit_log = "missing/audit.jsonl"\n[http]\nlisten = "127.0.0.1:0"\n'
    (here / "gateway.toml").write_text(text + _LINE)
    line = _same_as_a_start(capsys, "gateway.toml")
    assert line == "cannot serve: No such file or directory: missing/audit.jsonl"


def test_a_file_where_the_trip_records_would_go(
    here: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    (here / "trips").write_text("not a directory")
    (here / "gateway.toml").write_text('[http]\nlisten = "127.0.0.1:0"\n' + _LINE)
    line = _same_as_a_start(capsys, "gateway.toml")
    assert line == "cannot serve: Not a directory: trips"


def test_a_good_file_is_summarised_and_nothing_is_left_behind(
    here: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    with socket.socket() as free:
        free.bind(("127.0.0.1", 0))
        port = free.getsockname()[1]
    text = textwrap.dedent(
        f"""
        [gateway]
        id = "gw1"
        audit_log = "audit.jsonl"
        [modbus]
        listen = "127.0.0.1:{port}"
        [opcua]
        endpoint = "opc.tcp://127.0.0.1:0"
        [mqtt]
        url = "mqtt://127.0.0.1:1"
        [[lines]]
        name = "l1"
        url = "serial://{here}/ttyUSB-not-here"
        nodes = "1-4"
        [[lines.writes]]
        nodes = "1-2"
        control = true
        [[lines]]
        name = "l2"
        url = "sim://?nodes=1-2"
        nodes = "1-2"
        unit_offset = 10
        """
    )
    (here / "gateway.toml").write_text(text)
    status, out, err = _run(capsys, "--check-config", "gateway.toml")
    assert status == 0, err
    assert out.splitlines() == [
        "gateway.toml: the gateway would start",
        "  gateway gw1: 2 line(s), 6 drive(s), stale after 5 s",
        f"  line l1: sj300 on serial://{here}/ttyUSB-not-here, 4 drive(s), every 0.5 s, "
        "writes granted on 2 drive(s)",
        "  line l2: sj300 on sim://?nodes=1-2, 2 drive(s), every 0.5 s, read-only",
        f"  modbus: listens on 127.0.0.1:{port}",
        "  mqtt: to mqtt://127.0.0.1:1 as sj300-gw1, not contacted by the check",
        "  opcua: listens on 127.0.0.1:0; certificate opcua/cert.der: none yet, "
        "generated at the first start",
        "  audit log: audit.jsonl",
        "  recorder: trip records in trips, 60 s before and 10 s after each, at most 1000",
    ]
    assert err == (
        f"warning: line l1: {here}/ttyUSB-not-here does not exist now: the gateway would "
        "start, serve the line as down and retry\n"
    )
    # Nothing made, nothing held: no certificate, no audit log, the port free.
    assert sorted(p.name for p in here.iterdir()) == ["gateway.toml"]
    with socket.socket() as again:
        again.bind(("127.0.0.1", port))


def test_a_certificate_pair_that_loads_is_named_with_its_thumbprint(
    here: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from sj300_async.gateway.opcua._certificate import load_or_generate

    pair = load_or_generate(here / "c.der", here / "k.pem", "urn:test:gw")
    text = '[opcua]\nendpoint = "opc.tcp://127.0.0.1:0"\ncertificate = "c.der"\n'
    (here / "gateway.toml").write_text(text + 'private_key = "k.pem"\n' + _LINE)
    status, out, err = _run(capsys, "--check-config", "gateway.toml")
    assert (status, err) == (0, "")
    assert f"certificate c.der for urn:test:gw, thumbprint {pair.thumbprint}" in out


def test_check_config_takes_no_other_description(
    here: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    (here / "gateway.toml").write_text(_LINE)
    status, _, err = _run(capsys, "--check-config", "gateway.toml", "--url", "sim://")
    assert status == 2
    assert err == "sj300 gateway: error: --check-config FILE checks that file alone: no --url\n"


def test_as_a_user_runs_it(here: Path) -> None:
    """The installed command: one line on stderr, no traceback, exit 2; then exit 0."""
    (here / "gateway.toml").write_text('[modbus]\nlistn = ":502"\n')
    bad = asyncio.run(sj300("gateway", "--check-config", str(here / "gateway.toml")))
    assert bad.code == 2
    assert bad.err == (
        f"sj300 gateway: error: {here}/gateway.toml:2: modbus.listn: unknown key 'listn' "
        "(did you mean 'listen'?)\n"
    )
    (here / "gateway.toml").write_text('[modbus]\nlisten = "127.0.0.1:0"\n' + _LINE)
    good = asyncio.run(sj300("gateway", "--check-config", str(here / "gateway.toml")))
    assert (good.code, good.err) == (0, "")
    assert good.out.startswith(f"{here}/gateway.toml: the gateway would start\n")


def test_under_systemd_the_generated_certificate_goes_to_the_state_directory(
    here: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """``$STATE_DIRECTORY`` (StateDirectory=): the default pair is made there, since the
    configuration's directory is read-only under ProtectSystem=strict; a pair the file
    names stays relative to the file."""
    state = here / "state"
    state.mkdir()
    monkeypatch.setenv("STATE_DIRECTORY", f"{state}:{here}/second")
    (here / "gateway.toml").write_text('[opcua]\nendpoint = "opc.tcp://127.0.0.1:0"\n' + _LINE)
    status, out, _ = _run(capsys, "--check-config", "gateway.toml")
    assert status == 0
    assert f"certificate {state}/opcua/cert.der: none yet" in out
    text = '[opcua]\nendpoint = "opc.tcp://127.0.0.1:0"\ncertificate = "mine/c.der"\n'
    (here / "gateway.toml").write_text(text + 'private_key = "mine/k.pem"\n' + _LINE)
    status, out, _ = _run(capsys, "--check-config", "gateway.toml")
    assert status == 0
    assert "certificate mine/c.der: none yet" in out
