"""The gateway's configuration: what a valid file builds, and every refusal's exact message."""

from __future__ import annotations

import pickle
import socket
import textwrap
from pathlib import Path

import pytest
from waiting import wait_for

from sj300_async.gateway import (
    Endpoint,
    Gateway,
    GatewayConfig,
    GatewayConfigError,
    LineConfig,
    WriteGrant,
    config_from_flags,
    default_gateway_id,
    load_config,
    parse_config,
    parse_endpoint,
)
from sj300_async.gateway.http import HttpConfig
from sj300_async.gateway.modbus import ModbusConfig
from sj300_async.gateway.mqtt import MqttConfig
from sj300_async.gateway.mqtt._intake import Budget
from sj300_async.gateway.recorder import RecorderConfig
from sj300_async.wire import LocalProtocolError

FULL = """\
# The plant's gateway.
[gateway]
stale_after_s = 3      # seconds
audit_log = "logs/audit.log"

[modbus]
listen = "0.0.0.0:1502"

[metrics]
listen = "[::1]:9300"

[[lines]]
name = "hall-a"
url = "tcp://10.0.0.5:4001?baudrate=19200"
nodes = "1-4,12"
interval_s = 0.25
reads = ["monitor"]
parameters = [
    "f001",   # set frequency
    "A004",
]
trips_interval_s = 0
unit_offset = 10
timeout_s = 0.3
lease_s = 2.5
on_lapse = "broadcast_stop"

  [[lines.writes]]
  nodes = "1-2"
  parameters = ["a004"]
  control = true

  [[lines.writes]]
  nodes = [2, 12]
  parameters = ["F001"]

[[lines]]
url = "serial:///dev/ttyUSB0?protocol=fr700"
nodes = [0, 3, 1]
parameters = ["pr.7"]
on_lapse = "hold"
"""


def parse(text: str) -> GatewayConfig:
    return parse_config(textwrap.dedent(text), "gateway.toml")


def mqtt_of(config: GatewayConfig) -> MqttConfig:
    """The configuration of the MQTT northbound (its ``[mqtt]`` section)."""
    mqtt = config.northbounds["mqtt"]
    assert isinstance(mqtt, MqttConfig)
    return mqtt


def refusal(text: str) -> str:
    with pytest.raises(GatewayConfigError) as caught:
        parse(text)
    return str(caught.value)


# -- valid configurations ----------------------------------------------------------------------


def test_a_full_file_reaches_every_field(tmp_path: Path) -> None:
    path = tmp_path / "gateway.toml"
    path.write_text(FULL, encoding="utf-8")

    config = load_config(path)

    assert config == GatewayConfig(
        lines=(
            LineConfig(
                name="hall-a",
                url="tcp://10.0.0.5:4001?baudrate=19200",
                protocol="sj300",
                nodes=(1, 2, 3, 4, 12),
                interval_s=0.25,
                reads=("monitor",),
                parameters=("F001", "A004"),
                trips_interval_s=0.0,
                unit_offset=10,
                timeout_s=0.3,
                grants=(
                    WriteGrant(
                        nodes=frozenset({1, 2}), parameters=frozenset({"A004"}), control=True
                    ),
                    WriteGrant(nodes=frozenset({2, 12}), parameters=frozenset({"F001"})),
                ),
                lease_s=2.5,
                on_lapse="broadcast_stop",
            ),
            LineConfig(
                name="line2",
                url="serial:///dev/ttyUSB0?protocol=fr700",
                protocol="fr700",
                nodes=(0, 1, 3),
                parameters=("Pr.7",),
                unit_offset=100,
                on_lapse="hold",
            ),
        ),
        northbounds={
            "modbus": ModbusConfig(Endpoint("0.0.0.0", 1502)),
            "http": HttpConfig(Endpoint("::1", 9300)),
        },
        stale_after_s=3.0,
        audit_log=tmp_path / "logs" / "audit.log",
        recorder=RecorderConfig(directory=tmp_path / "trips"),  # beside the file
    )
    assert config.source == str(path)
    assert config.lines[0].writable_parameters(2) == {"A004", "F001"}
    assert config.lines[0].control_allowed(1)
    assert not config.lines[0].control_allowed(12)


def test_defaults_of_a_minimal_file() -> None:
    config = parse(
        """\
        [[lines]]
        url = "tcp://10.0.0.5:4001"
        nodes = "1-2"

        [[lines]]
        url = "tcp://10.0.0.6:4001"
        protocol = "fr700"
        nodes = "0-1"
        """
    )

    assert config == GatewayConfig(
        lines=(
            LineConfig(name="line1", url="tcp://10.0.0.5:4001", protocol="sj300", nodes=(1, 2)),
            LineConfig(
                name="line2",
                url="tcp://10.0.0.6:4001",
                protocol="fr700",
                nodes=(0, 1),
                unit_offset=100,
            ),
        ),
        recorder=RecorderConfig(),  # text, not a file: in memory
    )
    assert (dict(config.northbounds), config.audit_log) == ({}, None)
    assert config.source == "gateway.toml"
    assert [config.lines[1].unit(node) for node in (0, 1)] == [100, 101]


def test_audit_log_is_relative_to_the_file_unless_absolute(tmp_path: Path) -> None:
    lines = '[[lines]]\nurl = "sim://"\nnodes = "1"\n'
    relative = parse_config(f'[gateway]\naudit_log = "a.log"\n{lines}', str(tmp_path / "g.toml"))
    absolute = parse_config(f'[gateway]\naudit_log = "/var/a.log"\n{lines}', "conf/g.toml")

    assert relative.audit_log == tmp_path / "a.log"
    assert absolute.audit_log == Path("/var/a.log")


def test_a_line_can_be_an_inline_table() -> None:
    config = parse('lines = [{ url = "sim://", nodes = [3, 1], reads = [] }]\n')

    assert config.lines[0].nodes == (1, 3)
    assert config.lines[0].reads == ()


def test_mqtt_defaults_follow_the_gateway_id_and_the_scheme() -> None:
    config = parse('[gateway]\nid = "gw1"\n[mqtt]\nurl = "mqtt://10.0.0.9"\n' + LINE)

    assert config.gateway_id == "gw1"
    assert mqtt_of(config) == MqttConfig(host="10.0.0.9", port=1883, client_id="sj300-gw1")
    assert mqtt_of(config).url == "mqtt://10.0.0.9:1883"
    assert mqtt_of(parse('[mqtt]\nurl = "mqtts://[::1]"\n' + LINE)) == MqttConfig(
        host="::1", port=8883, tls=True, client_id=f"sj300-{default_gateway_id()}"
    )


def test_mqtt_every_key(tmp_path: Path) -> None:
    (tmp_path / "ca.pem").write_text("not checked until connect\n", encoding="utf-8")
    text = f"""\
        [gateway]
        id = "hall-a.gw"
        [mqtt]
        url = "mqtt://broker.plant:1884"
        client_id = "gateway-7"
        username = "sj300"
        password = "secret"
        tls_ca = "ca.pem"
        prefix = "plant/drives"
        qos = 0
        discovery = false
        discovery_prefix = "ha"
        keepalive_s = 5
        command_burst = 50
        commands_per_s = 40
        all_command_burst = 500
        all_commands_per_s = 400
        {LINE}"""
    config = parse_config(textwrap.dedent(text), str(tmp_path / "g.toml"))

    assert config.gateway_id == "hall-a.gw"
    assert mqtt_of(config) == MqttConfig(
        host="broker.plant",
        port=1884,
        tls=True,  # a CA means TLS, whatever the scheme
        client_id="gateway-7",
        username="sj300",
        password="secret",
        tls_ca=tmp_path / "ca.pem",
        prefix="plant/drives",
        qos=0,
        discovery=False,
        discovery_prefix="ha",
        keepalive_s=5,
        commands=Budget(burst=50, per_s=40, all_burst=500, all_per_s=400),
    )
    assert "secret" not in repr(config.northbounds)
    assert mqtt_of(parse('[mqtt]\nurl = "mqtt://b"\ntls_ca = "/etc/hostname"\n' + LINE)) == (
        MqttConfig(
            host="b",
            port=8883,  # the TLS port: a CA implies TLS
            tls=True,
            client_id=f"sj300-{default_gateway_id()}",
            tls_ca=Path("/etc/hostname"),
        )
    )


def test_the_default_gateway_id_is_a_topic_level(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(socket, "gethostname", lambda: "plc+7.plant.example")
    assert default_gateway_id() == "plc-7"
    monkeypatch.setattr(socket, "gethostname", lambda: "#")
    assert default_gateway_id() == "gateway"
    assert parse(LINE).gateway_id == "gateway"


def test_a_byte_order_mark_is_tolerated(tmp_path: Path) -> None:
    path = tmp_path / "bom.toml"
    path.write_bytes(b'\xef\xbb\xbf[[lines]]\nurl = "sim://"\nnodes = "1"\n')

    assert load_config(path).lines[0].nodes == (1,)


# -- refusals: every message is exact, with its line and key ----------------------------------

LINE = '[[lines]]\nurl = "tcp://10.0.0.5:4001"\nnodes = "1-8"\n'
#: A Modbus server: only then are unit ids checked (1..247, unique across lines).
MODBUS = '[modbus]\nlisten = "127.0.0.1:0"\n'

REFUSALS = [
    pytest.param(
        '[gateway]\nstale_after_s = 5\n[modbuss]\nlisten = ":502"\n',
        "gateway.toml:3: modbuss: unknown key 'modbuss' (did you mean 'modbus'?)",
        id="unknown-table",
    ),
    pytest.param(
        '[modbus]\n# the SCADA side\nlistn = ":502"\n',
        "gateway.toml:3: modbus.listn: unknown key 'listn' (did you mean 'listen'?)",
        id="unknown-key-did-you-mean",
    ),
    pytest.param(
        '[http]\nlisten = "127.0.0.1:1"\n[metrics]\nlisten = "127.0.0.1:2"\n',
        "gateway.toml:3: metrics: [http] and [metrics] are one section: keep one",
        id="http-and-its-old-name",
    ),
    pytest.param(
        '[http]\nlisten = "127.0.0.1:1"\ntrend_s = 86401\n',
        "gateway.toml:3: http.trend_s: must be <= 86400 (a day), got 86401",
        id="trend-longer-than-a-day",
    ),
    pytest.param(
        "[metrics]\nport = 9300\n",
        "gateway.toml:2: metrics.port: unknown key 'port' "
        "(use listen, max_connections, max_connections_per_address, idle_timeout_s, "
        "body_timeout_s, max_streams_per_address, trend_s, users, tokens, tls_cert, tls_key)",
        id="unknown-key-no-close-match",
    ),
    pytest.param(
        LINE + "intervl_s = 1\n",
        "gateway.toml:4: lines[0].intervl_s: unknown key 'intervl_s' (did you mean 'interval_s'?)",
        id="unknown-line-key",
    ),
    pytest.param(
        '[gateway]\nstale_after_s = "5"\n',
        "gateway.toml:2: gateway.stale_after_s: expected a number, got string",
        id="string-for-number",
    ),
    pytest.param(
        "[gateway]\nstale_after_s = true\n",
        "gateway.toml:2: gateway.stale_after_s: expected a number, got boolean",
        id="boolean-is-not-a-number",
    ),
    pytest.param(
        "[gateway]\nstale_after_s = 0\n",
        "gateway.toml:2: gateway.stale_after_s: must be > 0, got 0",
        id="stale-after-zero",
    ),
    pytest.param(
        "[gateway]\nstale_after_s = nan\n",
        "gateway.toml:2: gateway.stale_after_s: expected a finite number, got nan",
        id="stale-after-nan",
    ),
    pytest.param(
        "[gateway]\nstale_after_s = 1" + "0" * 400 + "\n",
        "gateway.toml:2: gateway.stale_after_s: expected a finite number, got 1" + "0" * 400,
        id="integer-too-large",
    ),
    pytest.param(
        '[gateway]\naudit_log = " "\n',
        "gateway.toml:2: gateway.audit_log: expected a file name, got an empty string",
        id="audit-log-empty",
    ),
    pytest.param(
        "[gateway]\naudit_log = 5\n",
        "gateway.toml:2: gateway.audit_log: expected a string, got integer",
        id="audit-log-not-a-string",
    ),
    pytest.param(
        "gateway = 5\n",
        "gateway.toml:1: gateway: expected a table, got integer",
        id="section-not-a-table",
    ),
    pytest.param(
        "[modbus]\n",
        "gateway.toml:1: modbus.listen: missing required key 'listen'",
        id="listen-missing",
    ),
    pytest.param(
        '[modbus]\nlisten = "localhost"\n',
        "gateway.toml:2: modbus.listen: expected HOST:PORT, got 'localhost'",
        id="listen-without-port",
    ),
    pytest.param(
        '[metrics]\nlisten = "127.0.0.1:70000"\n',
        "gateway.toml:2: metrics.listen: port must be 0..65535, got '70000'",
        id="listen-port-too-large",
    ),
    pytest.param(
        '[modbus]\nlisten = ":502"\n[metrics]\nlisten = "127.0.0.1:502"\n',
        "gateway.toml:4: metrics.listen: modbus.listen already listens on 0.0.0.0:502",
        id="metrics-on-the-modbus-port",
    ),
    pytest.param(
        "[gateway]\nstale_after_s = 5\n",
        "gateway.toml: lines: no lines: add a [[lines]] table with a url and nodes",
        id="no-lines",
    ),
    pytest.param(
        "lines = []\n",
        "gateway.toml:1: lines: no lines: add a [[lines]] table with a url and nodes",
        id="empty-lines",
    ),
    pytest.param(
        '[lines]\nurl = "sim://"\n',
        "gateway.toml:1: lines: expected an array of tables ([[lines]]), got table",
        id="lines-is-a-table",
    ),
    pytest.param(
        "lines = [5]\n",
        "gateway.toml:1: lines[0]: expected a table, got integer",
        id="line-not-a-table",
    ),
    pytest.param(
        '# first line\n[[lines]]\nnodes = "1-8"\n',
        "gateway.toml:2: lines[0].url: missing required key 'url'",
        id="url-missing-points-at-the-header",
    ),
    pytest.param(
        '[[lines]]\nurl = "ftp://x"\nnodes = "1"\n',
        "gateway.toml:2: lines[0].url: unknown bus URL scheme 'ftp' in 'ftp://x' "
        "(use tcp://, rfc2217://, serial://, sim://, replay://)",
        id="bad-url",
    ),
    pytest.param(
        '[[lines]]\nurl = "tcp://h:1?terminator=cr"\nnodes = "1"\n',
        "gateway.toml:2: lines[0].url: terminator in 'tcp://h:1?terminator=cr' are options "
        "of protocol fr700: add protocol=fr700",
        id="url-option-of-another-protocol",
    ),
    pytest.param(
        LINE + 'protocol = "fr7000"\n',
        "gateway.toml:4: lines[0].protocol: unknown protocol 'fr7000' (did you mean 'fr700'?)",
        id="unknown-protocol",
    ),
    pytest.param(
        '[[lines]]\nprotocol = "sj300"\nurl = "tcp://h:1?protocol=fr700"\nnodes = "1"\n',
        "gateway.toml:3: lines[0].url: protocol='sj300' but the URL says protocol=fr700",
        id="protocol-differs-from-the-url",
    ),
    pytest.param(
        LINE + 'name = "hall a"\n',
        "gateway.toml:4: lines[0].name: a line name is letters, digits, '_', '.' and '-', "
        "got 'hall a'",
        id="bad-line-name",
    ),
    pytest.param(
        LINE + '[[lines]]\nname = "line1"\nurl = "sim://"\nnodes = "1"\n',
        "gateway.toml:5: lines[1].name: duplicate line name 'line1' (also lines[0])",
        id="name-repeats-a-default",
    ),
    pytest.param(
        LINE + 'name = "hall.a"\n[[lines]]\nname = "hall_a"\nurl = "sim://"\nnodes = "1"\n',
        "gateway.toml:6: lines[1].name: 'hall_a' and 'hall.a' (lines[0]) are one name in "
        "Home Assistant's ids (hall_a): name the lines apart",
        id="line-names-alike-in-home-assistant",
    ),
    pytest.param(
        LINE + 'name = "Hall-A"\n[[lines]]\nname = "hall_a"\nurl = "sim://"\nnodes = "1"\n',
        "gateway.toml:6: lines[1].name: 'hall_a' and 'Hall-A' (lines[0]) are one name in "
        "Home Assistant's ids (hall_a): name the lines apart",
        id="line-names-alike-but-for-case",
    ),
    pytest.param(
        LINE + 'name = "line2"\n[[lines]]\nurl = "sim://"\nnodes = "1"\n',
        "gateway.toml:5: lines[1].name: duplicate line name 'line2' (also lines[0])",
        id="default-name-taken",
    ),
    pytest.param(
        LINE + '[[lines]]\nurl = "tcp://10.0.0.5:4001?baudrate=9600"\nnodes = "9"\n',
        "gateway.toml:5: lines[1].url: tcp://10.0.0.5:4001 is already line line1's "
        "(a line is one [[lines]] with all its nodes)",
        id="two-lines-one-url",
    ),
    pytest.param(
        '[[lines]]\nurl = "sim://"\n',
        "gateway.toml:1: lines[0].nodes: missing required key 'nodes'",
        id="nodes-missing",
    ),
    pytest.param(
        '[[lines]]\nurl = "sim://"\nnodes = "1-40"\n',
        "gateway.toml:3: lines[0].nodes: bad node list '1-40': nodes are 1..32, got '1-40'",
        id="node-list-out-of-range",
    ),
    pytest.param(
        '[[lines]]\nurl = "sim://"\nnodes = [1, 40]\n',
        "gateway.toml:3: lines[0].nodes: node 40 is outside 1..32",
        id="node-array-out-of-range",
    ),
    pytest.param(
        '[[lines]]\nurl = "sim://"\nprotocol = "fr700"\nnodes = [0, 32]\n',
        "gateway.toml:4: lines[0].nodes: station 32 is outside 0..31",
        id="fr700-station-out-of-range",
    ),
    pytest.param(
        '[[lines]]\nurl = "sim://"\nnodes = 5\n',
        'gateway.toml:3: lines[0].nodes: expected a node list ("1-8,12") or an array of '
        "integers, got integer",
        id="nodes-wrong-type",
    ),
    pytest.param(
        '[[lines]]\nurl = "sim://"\nnodes = [1, "2"]\n',
        "gateway.toml:3: lines[0].nodes: expected an array of integers, got string '2' in it",
        id="nodes-array-of-strings",
    ),
    pytest.param(
        '[[lines]]\nurl = "sim://"\nnodes = []\n',
        "gateway.toml:3: lines[0].nodes: no nodes",
        id="nodes-empty",
    ),
    pytest.param(
        LINE + "interval_s = 0.01\n",
        "gateway.toml:4: lines[0].interval_s: must be >= 0.05, got 0.01",
        id="interval-too-short",
    ),
    pytest.param(
        LINE + 'reads = ["stats"]\n',
        "gateway.toml:4: lines[0].reads: unknown read 'stats' (did you mean 'status'?)",
        id="unknown-read",
    ),
    pytest.param(
        LINE + 'reads = "status"\n',
        "gateway.toml:4: lines[0].reads: expected an array of strings, got string",
        id="reads-not-an-array",
    ),
    pytest.param(
        LINE + 'parameters = ["A004", 7]\n',
        "gateway.toml:4: lines[0].parameters: expected an array of strings, got integer 7 in it",
        id="parameters-not-strings",
    ),
    pytest.param(
        LINE + 'parameters = ["Pr.7"]\n',
        "gateway.toml:4: lines[0].parameters: unknown parameter 'Pr.7' for sj300",
        id="unknown-parameter-sj300",
    ),
    pytest.param(
        '[[lines]]\nurl = "sim://?protocol=fr700"\nnodes = "1"\nparameters = ["A004"]\n',
        "gateway.toml:4: lines[0].parameters: unknown parameter 'A004' for fr700",
        id="unknown-parameter-fr700",
    ),
    pytest.param(
        LINE + 'parameters = ["F001", "F005"]\n',
        "gateway.toml:4: lines[0].parameters: unknown parameter 'F005' for sj300",
        id="parameter-not-in-the-catalogue-sj300",  # a code SJ300 could spell, none it has
    ),
    pytest.param(
        '[[lines]]\nurl = "sim://?protocol=fr700"\nnodes = "1"\nparameters = ["Pr.999"]\n',
        "gateway.toml:4: lines[0].parameters: unknown parameter 'Pr.999' for fr700",
        id="parameter-not-in-the-catalogue-fr700",
    ),
    pytest.param(
        LINE + '[[lines.writes]]\nnodes = "1"\nparameters = ["F005"]\n',
        "gateway.toml:6: lines[0].writes[0].parameters: unknown parameter 'F005' for sj300",
        id="grant-parameter-not-in-the-catalogue",
    ),
    pytest.param(
        '[[lines]]\nurl = "sim://"\n\nnodes = "1-4,3"\n',
        "gateway.toml:4: lines[0].nodes: node 3 is listed twice",
        id="nodes-repeated-in-a-list",
    ),
    pytest.param(
        '[[lines]]\nurl = "sim://"\nnodes = [1, 2, 1]\n',
        "gateway.toml:3: lines[0].nodes: node 1 is listed twice",
        id="nodes-repeated-in-an-array",
    ),
    pytest.param(
        '[[lines]]\nurl = "sim://?protocol=fr700"\nnodes = "0-3, 2-5"\n',
        "gateway.toml:3: lines[0].nodes: station 2 is listed twice",
        id="stations-repeated",
    ),
    pytest.param(
        LINE + '[[lines.writes]]\nnodes = "1,1"\ncontrol = true\n',
        "gateway.toml:5: lines[0].writes[0].nodes: node 1 is listed twice",
        id="grant-nodes-repeated",
    ),
    pytest.param(
        '[gateway]\nid = "gw1"\n\nmodbus.listen = ":502"\n' + LINE,
        "gateway.toml:4: gateway.modbus: unknown key 'modbus' "
        "(use id, stale_after_s, audit_log, loop_lag_limit_s)",
        id="dotted-key-under-a-table",  # [gateway]'s, not the top level's: its own line
    ),
    pytest.param(
        '# the plant\n\nmodbuss.listen = ":502"\n' + LINE,
        "gateway.toml:3: modbuss: unknown key 'modbuss' (did you mean 'modbus'?)",
        id="dotted-key-unknown-table",
    ),
    pytest.param(
        '\n\nlines.hall.url = "sim://"\n',
        "gateway.toml:3: lines: expected an array of tables ([[lines]]), got table",
        id="dotted-key-makes-a-table",
    ),
    pytest.param(
        LINE + "\nwrites.nodes = 1\n",
        "gateway.toml:5: lines[0].writes: expected an array of tables ([[lines.writes]]), "
        "got table",
        id="dotted-key-in-an-array-of-tables",
    ),
    pytest.param(
        LINE + "trips_interval_s = -1\n",
        "gateway.toml:4: lines[0].trips_interval_s: must be >= 0, got -1",
        id="trips-interval-negative",
    ),
    pytest.param(
        LINE + "unit_offset = 1.5\n",
        "gateway.toml:4: lines[0].unit_offset: expected an integer, got float",
        id="unit-offset-not-an-integer",
    ),
    pytest.param(
        MODBUS + '[[lines]]\nurl = "sim://"\nnodes = "1-32"\nunit_offset = 220\n',
        "gateway.toml:6: lines[0].unit_offset: node 28 would be Modbus unit 248, outside 1..247",
        id="unit-above-247",
    ),
    pytest.param(
        MODBUS + LINE + "unit_offset = -1\n",
        "gateway.toml:6: lines[0].unit_offset: node 1 would be Modbus unit 0, outside 1..247",
        id="unit-zero-is-broadcast",
    ),
    pytest.param(
        LINE + "timeout_s = 0\n",
        "gateway.toml:4: lines[0].timeout_s: must be > 0, got 0",
        id="timeout-zero",
    ),
    pytest.param(
        LINE + "lease_s = -1\n",
        "gateway.toml:4: lines[0].lease_s: must be > 0, got -1",
        id="lease-negative",
    ),
    pytest.param(
        LINE + 'on_lapse = "stops"\n',
        "gateway.toml:4: lines[0].on_lapse: unknown action 'stops' (did you mean 'stop'?)",
        id="unknown-lapse-action",
    ),
    pytest.param(
        '[[lines]]\nurl = "sim://"\nprotocol = "fr700"\nnodes = "1"\non_lapse = "broadcast_stop"\n',
        "gateway.toml:5: lines[0].on_lapse: broadcast_stop needs a broadcast, which fr700 has not",
        id="broadcast-stop-on-fr700",
    ),
    pytest.param(
        LINE + 'writes = "all"\n',
        "gateway.toml:4: lines[0].writes: expected an array of tables ([[lines.writes]]), "
        "got string",
        id="writes-not-tables",
    ),
    pytest.param(
        LINE + "[[lines.writes]]\ncontroll = true\n",
        "gateway.toml:5: lines[0].writes[0].controll: unknown key 'controll' "
        "(did you mean 'control'?)",
        id="unknown-grant-key",
    ),
    pytest.param(
        LINE + "[[lines.writes]]\ncontrol = true\n",
        "gateway.toml:4: lines[0].writes[0].nodes: missing required key 'nodes'",
        id="grant-nodes-missing",
    ),
    pytest.param(
        LINE + '[[lines.writes]]\nnodes = "8-9"\ncontrol = true\n',
        "gateway.toml:5: lines[0].writes[0].nodes: node 9 is not one of line line1's nodes (1-8)",
        id="grant-node-not-on-the-line",
    ),
    pytest.param(
        LINE + 'name = "hall-a"\n[[lines.writes]]\nnodes = "1"\nparameters = ["A004"]\n',
        "gateway.toml:7: lines[0].writes[0].parameters: A004 is not polled on line hall-a: "
        "add it to parameters",
        id="grant-parameter-not-polled",
    ),
    pytest.param(
        LINE + '[[lines.writes]]\nnodes = "1"\nparameters = ["X1"]\n',
        "gateway.toml:6: lines[0].writes[0].parameters: unknown parameter 'X1' for sj300",
        id="grant-parameter-unknown",
    ),
    pytest.param(
        LINE + '[[lines.writes]]\nnodes = "1"\ncontrol = "yes"\n',
        "gateway.toml:6: lines[0].writes[0].control: expected true or false, got string",
        id="grant-control-not-a-boolean",
    ),
    pytest.param(
        LINE + '[[lines.writes]]\nnodes = "1"\n',
        "gateway.toml:4: lines[0].writes[0]: grants nothing: give it parameters, or control = true",
        id="grant-grants-nothing",
    ),
    # MQTT: the gateway id and line names are topic levels; the broker's URL and options.
    pytest.param(
        '[gateway]\nid = "plant/gw1"\n',
        "gateway.toml:2: gateway.id: a gateway id is letters, digits, '_', '.' and '-', "
        "got 'plant/gw1'",
        id="gateway-id-with-a-separator",
    ),
    pytest.param(
        '[gateway]\nid = "gw+"\n',
        "gateway.toml:2: gateway.id: a gateway id is letters, digits, '_', '.' and '-', got 'gw+'",
        id="gateway-id-with-a-wildcard",
    ),
    pytest.param(
        '[mqtt]\nurl = "mqtt://broker"\n' + LINE + 'name = "hall/a"\n',
        "gateway.toml:6: lines[0].name: a line name is letters, digits, '_', '.' and '-', "
        "got 'hall/a'",
        id="line-name-not-a-topic-level",
    ),
    pytest.param(
        '[mqtt]\nurl = "mqtt://broker"\n' + LINE + 'name = "#"\n',
        "gateway.toml:6: lines[0].name: a line name is letters, digits, '_', '.' and '-', got '#'",
        id="line-name-a-wildcard",
    ),
    pytest.param(
        "[mqtt]\nqos = 1\n",
        "gateway.toml:1: mqtt.url: missing required key 'url'",
        id="mqtt-url-missing",
    ),
    pytest.param(
        '[mqtt]\nurl = "tcp://broker:1883"\n',
        "gateway.toml:2: mqtt.url: expected mqtt://HOST[:PORT] or mqtts://HOST[:PORT], "
        "got 'tcp://broker:1883'",
        id="mqtt-url-scheme",
    ),
    pytest.param(
        '[mqtt]\nurl = "broker:1883"\n',
        "gateway.toml:2: mqtt.url: expected mqtt://HOST[:PORT] or mqtts://HOST[:PORT], "
        "got 'broker:1883'",
        id="mqtt-url-without-scheme",
    ),
    pytest.param(
        '[mqtt]\nurl = "mqtt://broker:18830000"\n',
        "gateway.toml:2: mqtt.url: expected mqtt://HOST[:PORT] or mqtts://HOST[:PORT], "
        "got 'mqtt://broker:18830000'",
        id="mqtt-url-port-too-large",
    ),
    pytest.param(
        '[mqtt]\nurl = "mqtt://broker:0"\n',
        "gateway.toml:2: mqtt.url: port must be 1..65535, got 0 in 'mqtt://broker:0'",
        id="mqtt-url-port-zero",
    ),
    pytest.param(
        '[mqtt]\nurl = "mqtt://broker/sj300"\n',
        "gateway.toml:2: mqtt.url: expected mqtt://HOST[:PORT] or mqtts://HOST[:PORT], "
        "got 'mqtt://broker/sj300'",
        id="mqtt-url-with-a-path",
    ),
    pytest.param(
        '[mqtt]\nurl = "mqtt://me:secret@broker"\n',
        "gateway.toml:2: mqtt.url: give the credentials as username and password, not in the URL",
        id="mqtt-url-with-credentials",
    ),
    pytest.param(
        '[mqtt]\nurl = "mqtt://broker"\nqos = 2\n',
        "gateway.toml:3: mqtt.qos: must be 0 or 1, got 2",
        id="mqtt-qos-2",
    ),
    pytest.param(
        '[mqtt]\nurl = "mqtt://broker"\nqos = "1"\n',
        "gateway.toml:3: mqtt.qos: expected an integer, got string",
        id="mqtt-qos-not-an-integer",
    ),
    pytest.param(
        '[mqtt]\nurl = "mqtt://broker"\nprefix = "plant/+"\n',
        "gateway.toml:3: mqtt.prefix: expected topic levels of letters, digits, '_', '.' and '-' "
        "separated by '/', got 'plant/+'",
        id="mqtt-prefix-wildcard",
    ),
    pytest.param(
        '[mqtt]\nurl = "mqtt://broker"\ndiscovery_prefix = "homeassistant/"\n',
        "gateway.toml:3: mqtt.discovery_prefix: expected topic levels of letters, digits, '_', "
        "'.' and '-' separated by '/', got 'homeassistant/'",
        id="mqtt-discovery-prefix-empty-level",
    ),
    pytest.param(
        '[mqtt]\nurl = "mqtt://broker"\npassword = "secret"\n',
        "gateway.toml:3: mqtt.password: a password needs a username",
        id="mqtt-password-without-username",
    ),
    pytest.param(
        '[mqtt]\nurl = "mqtt://broker"\ntls_ca = "/nonexistent/ca.pem"\n',
        "gateway.toml:3: mqtt.tls_ca: no such file: '/nonexistent/ca.pem'",
        id="mqtt-tls-ca-missing",
    ),
    pytest.param(
        '[mqtt]\nurl = "mqtt://broker"\nkeepalive_s = 0\n',
        "gateway.toml:3: mqtt.keepalive_s: must be 1..65535 seconds, got 0",
        id="mqtt-keepalive-zero",
    ),
    pytest.param(
        '[mqtt]\nurl = "mqtt://broker"\ndiscovery = "on"\n',
        "gateway.toml:3: mqtt.discovery: expected true or false, got string",
        id="mqtt-discovery-not-a-boolean",
    ),
    pytest.param(
        '[mqtt]\nurl = "mqtt://broker"\ncommands_per_s = 0\n',
        "gateway.toml:3: mqtt.commands_per_s: expected a whole number from 1 to 1,000,000, got 0",
        id="mqtt-commands-per-s-zero",
    ),
    pytest.param(
        '[mqtt]\nurl = "mqtt://broker"\nall_command_burst = 1000001\n',
        "gateway.toml:3: mqtt.all_command_burst: expected a whole number from 1 to 1,000,000, "
        "got 1000001",
        id="mqtt-all-command-burst-too-large",
    ),
    pytest.param(
        '[mqtt]\nurl = "mqtt://broker"\ncommand_burst = 2.5\n',
        "gateway.toml:3: mqtt.command_burst: expected an integer, got float",
        id="mqtt-command-burst-not-whole",
    ),
    pytest.param(
        '[mqtt]\nurl = "mqtt://broker"\nqoss = 1\n',
        "gateway.toml:3: mqtt.qoss: unknown key 'qoss' (did you mean 'qos'?)",
        id="mqtt-unknown-key",
    ),
]


@pytest.mark.parametrize(("text", "message"), REFUSALS)
def test_refusal(text: str, message: str) -> None:
    assert refusal(text) == message


def test_unit_ids_collide_across_lines() -> None:
    text = """\
        [modbus]
        listen = "127.0.0.1:0"
        [[lines]]
        name = "hall-a"
        url = "tcp://10.0.0.5:4001"
        nodes = "1-8"

        [[lines]]
        name = "hall-b"
        url = "tcp://10.0.0.6:4001"
        nodes = "8-9"
        """

    assert refusal(text) == (
        "gateway.toml:11: lines[1].nodes: Modbus unit 8 (node 8) is also line hall-a's (node 8): "
        "set unit_offset on one of them"
    )


def test_unit_ids_collide_across_protocols_when_the_offset_says_so() -> None:
    text = """\
        [modbus]
        listen = "127.0.0.1:0"
        [[lines]]
        name = "sj"
        url = "tcp://10.0.0.5:4001"
        nodes = "1-8"

        [[lines]]
        name = "fr"
        url = "tcp://10.0.0.6:4001"
        protocol = "fr700"
        nodes = "1-3"
        unit_offset = 0
        """

    assert refusal(text) == (
        "gateway.toml:13: lines[1].unit_offset: Modbus unit 1 (station 1) is also line sj's "
        "(node 1): set unit_offset on one of them"
    )


def test_the_default_offsets_keep_sj300_and_fr700_apart() -> None:
    config = parse(
        """\
        [[lines]]
        url = "tcp://10.0.0.5:4001"
        nodes = "1-32"

        [[lines]]
        url = "tcp://10.0.0.6:4001"
        protocol = "fr700"
        nodes = "0-31"
        """
    )

    units = [line.unit(node) for line in config.lines for node in line.nodes]
    assert len(set(units)) == 64


# -- the locator: line numbers past comments, multi-line values and nested tables -------------


def test_second_grant_of_the_second_line() -> None:
    text = """\
        [[lines]]
        url = "tcp://10.0.0.5:4001"
        nodes = "1-8"
        parameters = ["A004"]
          [[lines.writes]]
          nodes = "1"
          parameters = ["A004"]

        [[lines]]   # hall B
        url = "tcp://10.0.0.6:4001"
        nodes = "1-8"
        unit_offset = 8
          [[lines.writes]]
          nodes = "2"
          control = true
          [[lines.writes]]
          # nodes = "1"
          nodes = "9"
          control = true
        """

    assert refusal(text) == (
        "gateway.toml:18: lines[1].writes[1].nodes: node 9 is not one of line line2's nodes (1-8)"
    )


def test_a_multi_line_array_does_not_confuse_the_lines_after_it() -> None:
    text = """\
        [[lines]]
        url = "tcp://10.0.0.5:4001"
        parameters = [
            "A004",   # [not a table]
            "F001",
        ]
        nodes = "1-40"
        """

    assert refusal(text) == (
        "gateway.toml:7: lines[0].nodes: bad node list '1-40': nodes are 1..32, got '1-40'"
    )


def test_a_key_inside_an_inline_table_points_at_its_first_line() -> None:
    text = 'x = 1\nlines = [\n  { url = "sim://", nodes = "40" },\n]\n'

    assert refusal(text) == (
        "gateway.toml:1: x: unknown key 'x' "
        "(use gateway, modbus, http, metrics, mqtt, sparkplug, opcua, recorder, lines)"
    )
    assert refusal(text[6:]) == (
        "gateway.toml:1: lines[0].nodes: bad node list '40': nodes are 1..32, got '40'"
    )


# -- reading the file ------------------------------------------------------------------------


def test_a_toml_syntax_error_names_its_line() -> None:
    assert refusal('[[lines]]\nurl = "sim://"\nnodes = \n') == (
        "gateway.toml:3: invalid TOML: Invalid value (column 9)"
    )


def test_a_toml_error_at_the_end_names_the_last_line() -> None:
    assert refusal('[[lines]]\nurl = "sim://\n') == (
        "gateway.toml:2: invalid TOML: Illegal character '\\n' (column 14)"
    )
    assert (
        refusal('x = """\nopen')
        == "gateway.toml:2: invalid TOML: Unterminated string (at end of file)"
    )


def test_a_missing_file_is_named(tmp_path: Path) -> None:
    path = tmp_path / "nope.toml"

    with pytest.raises(GatewayConfigError) as caught:
        load_config(path)

    assert str(caught.value) == f"{path}: No such file or directory"
    assert (caught.value.line, caught.value.key) == (None, None)


def test_a_directory_is_not_a_file(tmp_path: Path) -> None:
    with pytest.raises(GatewayConfigError, match="Is a directory"):
        load_config(str(tmp_path))


def test_a_file_that_is_not_utf8(tmp_path: Path) -> None:
    path = tmp_path / "latin1.toml"
    path.write_bytes(b'[[lines]]\nname = "halle-\xe4"\n')

    with pytest.raises(GatewayConfigError) as caught:
        load_config(path)

    assert str(caught.value) == f"{path}:2: not UTF-8 text: invalid continuation byte"


def test_the_file_name_is_as_given(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)
    Path("gw.toml").write_text("[gateway]\nstale_after_s = -1\n", encoding="utf-8")

    with pytest.raises(GatewayConfigError) as caught:
        load_config("gw.toml")

    assert str(caught.value) == "gw.toml:2: gateway.stale_after_s: must be > 0, got -1"


# -- the error itself ------------------------------------------------------------------------


def test_the_error_is_one_line_in_every_form() -> None:
    assert (
        str(GatewayConfigError("g.toml", 3, "lines[0].url", "bad")) == "g.toml:3: lines[0].url: bad"
    )
    assert str(GatewayConfigError("g.toml", None, "lines", "bad")) == "g.toml: lines: bad"
    assert str(GatewayConfigError("g.toml", 3, None, "bad")) == "g.toml:3: bad"
    assert str(GatewayConfigError("g.toml", None, None, "bad")) == "g.toml: bad"


def test_the_error_is_a_value_error_that_pickles() -> None:
    error = GatewayConfigError("g.toml", 3, "modbus.listen", "bad")
    copy = pickle.loads(pickle.dumps(error))

    assert isinstance(error, LocalProtocolError)
    assert isinstance(error, ValueError)
    assert (copy.source, copy.line, copy.key, copy.reason) == ("g.toml", 3, "modbus.listen", "bad")
    assert str(copy) == str(error)


# -- the command line ------------------------------------------------------------------------


def test_flags_build_one_read_only_line() -> None:
    config = config_from_flags(
        url="sim://?nodes=1-4",
        nodes="1-4",
        protocol=None,
        northbounds={"modbus": ":0", "http": "127.0.0.1:0"},
        stale_after_s=2.0,
        interval_s=0.2,
    )

    assert config == GatewayConfig(
        lines=(
            LineConfig(
                name="line1",
                url="sim://?nodes=1-4",
                protocol="sj300",
                nodes=(1, 2, 3, 4),
                interval_s=0.2,
            ),
        ),
        northbounds={
            "modbus": ModbusConfig(Endpoint("0.0.0.0", 0)),
            "http": HttpConfig(Endpoint("127.0.0.1", 0)),
        },
        stale_after_s=2.0,
    )
    assert config.source == "<command line>"
    assert config.lines[0].grants == ()


def test_flags_with_mqtt_and_an_id() -> None:
    config = config_from_flags(
        url="sim://",
        nodes="1",
        protocol=None,
        northbounds={"mqtt": "mqtt://127.0.0.1:1884"},
        gateway_id="gw1",
    )

    assert mqtt_of(config) == MqttConfig(host="127.0.0.1", port=1884, client_id="sj300-gw1")
    assert config.gateway_id == "gw1"


def test_flags_with_fr700() -> None:
    config = config_from_flags(url="tcp://10.0.0.5:4001", nodes="0-2", protocol="fr700")

    assert (config.lines[0].protocol, config.lines[0].unit_offset) == ("fr700", 100)
    assert dict(config.northbounds) == {}


FLAG_DEFAULTS: dict[str, object] = {
    "url": "tcp://10.0.0.5:4001",
    "nodes": "1-8",
    "protocol": None,
    "northbounds": {"modbus": ":502"},
}


@pytest.mark.parametrize(
    ("flags", "message"),
    [
        pytest.param(
            {"nodes": "40"},
            "<command line>: --nodes: bad node list '40': nodes are 1..32, got '40'",
            id="nodes",
        ),
        pytest.param(
            {"url": "ftp://x"},
            "<command line>: --url: unknown bus URL scheme 'ftp' in 'ftp://x' "
            "(use tcp://, rfc2217://, serial://, sim://, replay://)",
            id="url",
        ),
        pytest.param(
            {"protocol": "modbus"},
            "<command line>: --protocol: unknown protocol 'modbus' (use fr700, sj300)",
            id="protocol",
        ),
        pytest.param(
            {"northbounds": {"modbus": "502"}},
            "<command line>: --modbus: expected HOST:PORT, got '502'",
            id="modbus",
        ),
        pytest.param(
            {"northbounds": {"modbus": ":502", "http": "0.0.0.0:502"}},
            "<command line>: --http: --modbus already listens on 0.0.0.0:502",
            id="metrics",
        ),
        pytest.param(
            {"stale_after_s": 0.0},
            "<command line>: --stale-after: must be > 0, got 0",
            id="stale-after",
        ),
        pytest.param(
            {"interval_s": 0.001},
            "<command line>: --interval: must be >= 0.05, got 0.001",
            id="interval",
        ),
        pytest.param(
            {"northbounds": {"modbus": ":502", "mqtt": "http://broker"}},
            "<command line>: --mqtt: expected mqtt://HOST[:PORT] or mqtts://HOST[:PORT], "
            "got 'http://broker'",
            id="mqtt",
        ),
        pytest.param(
            {"gateway_id": "a b"},
            "<command line>: --id: a gateway id is letters, digits, '_', '.' and '-', got 'a b'",
            id="id",
        ),
    ],
)
def test_flag_refusals_name_the_flag(flags: dict[str, object], message: str) -> None:
    arguments = {**FLAG_DEFAULTS, **flags}

    with pytest.raises(GatewayConfigError) as caught:
        config_from_flags(**arguments)  # type: ignore[arg-type]

    assert str(caught.value) == message
    assert caught.value.line is None


# -- endpoints -------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("text", "endpoint"),
    [
        ("127.0.0.1:9300", Endpoint("127.0.0.1", 9300)),
        ("[::1]:502", Endpoint("::1", 502)),
        (":502", Endpoint("0.0.0.0", 502)),
        (" localhost:0 ", Endpoint("localhost", 0)),
        ("[fe80::1%eth0]:65535", Endpoint("fe80::1%eth0", 65535)),
    ],
)
def test_parse_endpoint(text: str, endpoint: Endpoint) -> None:
    assert parse_endpoint(text) == endpoint
    assert parse_endpoint(str(endpoint)) == endpoint


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("localhost", "expected HOST:PORT, got 'localhost'"),
        ("::1:502", "put an IPv6 address in brackets: [::1]:502"),
        ("[::1]", "expected [IPV6]:PORT, got '[::1]'"),
        ("[::1]502", "expected [IPV6]:PORT, got '[::1]502'"),
        ("[]:502", "bad host '' in '[]:502'"),
        ("my host:502", "bad host 'my host' in 'my host:502'"),
        ("host:", "port must be 0..65535, got ''"),
        ("host:65536", "port must be 0..65535, got '65536'"),
        ("host:-1", "port must be 0..65535, got '-1'"),
        (
            "host:\uff15\uff10\uff12",
            "port must be 0..65535, got '\uff15\uff10\uff12'",
        ),  # full-width
    ],
)
def test_parse_endpoint_refuses(text: str, message: str) -> None:
    with pytest.raises(LocalProtocolError) as caught:
        parse_endpoint(text)

    assert str(caught.value) == message


def test_without_modbus_unit_ids_bind_nothing_and_a_plant_may_have_2048_drives() -> None:
    """Unit ids are Modbus's: 64 lines of 32 drives, each line's nodes 1..32, no offsets."""
    lines = "".join(
        f'[[lines]]\nname = "l{i}"\nurl = "tcp://10.0.{i // 250}.{i % 250 + 1}:4001"\n'
        'nodes = "1-32"\n'
        for i in range(64)
    )
    config = parse('[mqtt]\nurl = "mqtt://127.0.0.1:1"\n' + lines)
    assert sum(len(line.nodes) for line in config.lines) == 2048
    assert {line.unit(1) for line in config.lines} == {1}
    # The same plant with a Modbus server: refused, naming the first collision.
    message = refusal(MODBUS + lines)
    assert "lines[1].nodes: Modbus unit 1 (node 1) is also line l0's (node 1)" in message


def test_two_lines_may_each_simulate_the_same_url() -> None:
    """Each sim:// line is a simulator of its own: the URL names no shared transport."""
    simulated = '[[lines]]\nurl = "sim://?nodes=1-8"\nnodes = "1-8"\n'
    config = parse(simulated * 2)
    assert [line.url for line in config.lines] == ["sim://?nodes=1-8"] * 2
    assert [line.name for line in config.lines] == ["line1", "line2"]


async def test_two_lines_of_the_same_simulated_url_poll_drives_of_their_own() -> None:
    simulated = '[[lines]]\nurl = "sim://?nodes=1-2"\nnodes = "1-2"\ninterval_s = 0.05\n'
    async with Gateway(parse(simulated * 2)) as gateway:
        await wait_for(lambda: all(d.snapshot.available for d in gateway.drives), "samples")
        assert [d.key for d in gateway.drives] == [
            ("line1", 1), ("line1", 2), ("line2", 1), ("line2", 2),
        ]  # fmt: skip
        assert gateway.lines[0].bus is not gateway.lines[1].bus
