"""Our payloads as Eclipse Tahu reads them, Tahu's commands as we read them, and the section.

Tahu's JavaScript codec (sparkplug-payload) is the independent party: each
value the edge node encodes must decode there to the same value and type,
and each command form a host sends must decode here to the value it meant.
"""

from __future__ import annotations

import logging

import pytest

from sj300_async.gateway import GatewayConfigError, parse_config
from sj300_async.gateway.mqtt import MqttConfig
from sj300_async.gateway.sparkplug import (
    DATA_TYPES,
    MalformedPayload,
    MetricDef,
    Property,
    SparkplugConfig,
    decode_payload,
    encode_payload,
)

from .host import Codec

D = DATA_TYPES


async def test_each_datatype_the_edge_node_sends_reads_the_same_in_tahu(tahu: Codec) -> None:
    sent = [
        (MetricDef("bdSeq", None, D["Int64"]), 255),
        (MetricDef("negative", 1, D["Int64"]), -2),
        (MetricDef("count", 2, D["UInt64"]), 2**53),
        (MetricDef("node", 3, D["UInt32"]), 4_000_000_000),
        (MetricDef("hz", 4, D["Double"], (Property("engUnit", D["String"], "Hz"),
                                          Property("engHigh", D["Double"], 400.0))), 45.67),
        (MetricDef("running", 5, D["Boolean"]), True),
        (MetricDef("state", 6, D["String"]), "accelerating ✓"),
        (MetricDef("unknown", 7, D["Double"]), None),
    ]  # fmt: skip
    payload = encode_payload(1_800_000_000_123, 17, sent, birth=True)
    decoded = await tahu.decode(payload)
    assert (decoded["timestamp"], decoded["seq"]) == (1_800_000_000_123, 17)
    got = {m["name"]: m for m in decoded["metrics"]}
    for definition, value in sent:
        metric = got[definition.name]
        assert metric["value"] == value, definition.name
        types = {number: name for name, number in D.items()}
        assert metric["type"] == types[definition.datatype]
        assert metric["timestamp"] == 1_800_000_000_123
        assert ("alias" in metric) == (definition.alias is not None)
    assert got["hz"]["properties"] == {
        "engUnit": {"type": "String", "value": "Hz"},
        "engHigh": {"type": "Double", "value": 400.0},
    }
    # A data message: aliases, no names, no types; no seq at all in an NDEATH.
    data = await tahu.decode(encode_payload(5, 3, sent[1:3], birth=False))
    assert [sorted(m) for m in data["metrics"]] == [["alias", "timestamp", "value"]] * 2
    assert "seq" not in await tahu.decode(encode_payload(5, None, sent[:1], birth=True))


async def test_each_command_form_a_host_sends_reads_as_meant(tahu: Codec) -> None:
    payload = await tahu.encode({"timestamp": 9, "metrics": [
        {"alias": 65537, "type": "Double", "value": 25.5},
        {"name": "Control/Lease", "type": "Boolean", "value": True},
        {"alias": 65542, "type": "String", "value": "reverse"},
        {"alias": 70000, "type": "Int32", "value": 7},
        {"alias": 70001, "type": "Float", "value": 0.5},
        {"alias": 70002, "type": "Double", "value": None},
    ]})  # fmt: skip
    decoded = decode_payload(payload)
    assert decoded.timestamp_ms == 9
    assert decoded.seq is None
    seen = [(m.label, m.datatype, m.member, m.value, m.is_null) for m in decoded.metrics]
    assert seen == [
        ("alias 65537", D["Double"], "double_value", 25.5, False),
        ("Control/Lease", D["Boolean"], "boolean_value", True, False),
        ("alias 65542", D["String"], "string_value", "reverse", False),
        ("alias 70000", D["Int32"], "int_value", 7, False),
        ("alias 70001", D["Float"], "float_value", 0.5, False),
        ("alias 70002", D["Double"], None, None, True),
    ]


@pytest.mark.parametrize("data", [b"\xff\x01 no protobuf", b"\x0a\xff", b"\x12\x05\x0a\x03ab"])
def test_bytes_that_are_no_payload_are_refused(data: bytes) -> None:
    with pytest.raises(MalformedPayload):
        decode_payload(data)


def _northbounds(text: str) -> dict[str, object]:
    head = '[gateway]\nid = "gw1"\n'
    tail = '[[lines]]\nurl = "sim://"\nnodes = "1"\n'
    return dict(parse_config(head + text + tail, "gw.toml").northbounds)


def _alias(section: str) -> SparkplugConfig | None:
    """Sparkplug B as ``[mqtt] sparkplug = true`` configures it (deprecated), or None."""
    config = _northbounds(f'[mqtt]\nurl = "mqtt://127.0.0.1"\n{section}\n').get("sparkplug")
    assert config is None or isinstance(config, SparkplugConfig)
    return config


def _section(section: str) -> SparkplugConfig:
    config = _northbounds(f'[sparkplug]\nurl = "mqtt://127.0.0.1"\n{section}\n')["sparkplug"]
    assert isinstance(config, SparkplugConfig)
    return config


def test_the_section_takes_the_broker_the_group_and_the_host() -> None:
    config = _section('group_id = "Plant 1"\nprimary_host_id = "scada"\nkeepalive_s = 5')
    assert config == SparkplugConfig(
        host="127.0.0.1",
        port=1883,
        client_id="sj300-gw1-spb",
        keepalive_s=5,
        group_id="Plant 1",
        primary_host_id="scada",
    )
    assert _section('group_id = "g"\nclient_id = "edge"').client_id == "edge"


def test_the_deprecated_alias_configures_the_same_northbound_with_one_warning(
    caplog: pytest.LogCaptureFixture,
) -> None:
    caplog.set_level(logging.WARNING, "sj300_async.gateway.sparkplug")
    config = _alias('sparkplug = true\ngroup_id = "Plant 1"\nprimary_host_id = "scada"')
    assert config == SparkplugConfig(
        host="127.0.0.1",
        port=1883,
        client_id="sj300-gw1-spb",  # [mqtt]'s client id, with -spb: two connections
        group_id="Plant 1",
        primary_host_id="scada",
    )
    warnings = [r.getMessage() for r in caplog.records if r.levelno >= logging.WARNING]
    assert len(warnings) == 1
    assert "[mqtt] sparkplug = true is deprecated" in warnings[0]
    assert "[sparkplug]" in warnings[0]
    assert _alias("") is None
    given = _alias('client_id = "gw-7"\nsparkplug = true\ngroup_id = "g"')
    assert given is not None
    assert given.client_id == "gw-7-spb"


def test_the_alias_keeps_state_topics_false_meaning_sparkplug_only() -> None:
    both = _northbounds('[mqtt]\nurl = "mqtt://b"\nsparkplug = true\ngroup_id = "g"\n')
    assert isinstance(both["mqtt"], MqttConfig)
    assert isinstance(both["sparkplug"], SparkplugConfig)
    only = _northbounds(
        '[mqtt]\nurl = "mqtt://b"\nstate_topics = false\nsparkplug = true\ngroup_id = "g"\n'
    )
    assert "mqtt" not in only
    assert isinstance(only["sparkplug"], SparkplugConfig)


def test_the_section_and_the_alias_at_once_are_an_error() -> None:
    with pytest.raises(GatewayConfigError) as raised:
        _northbounds(
            '[mqtt]\nurl = "mqtt://b"\nsparkplug = true\ngroup_id = "g"\n'
            '[sparkplug]\nurl = "mqtt://b"\ngroup_id = "g"\n'
        )
    assert "[sparkplug] and the [mqtt] keys that configure it too are one northbound" in str(
        raised.value
    )


@pytest.mark.parametrize(
    ("section", "error"),
    [
        ("sparkplug = true", "mqtt.group_id: sparkplug = true needs a group_id"),
        ('sparkplug = true\ngroup_id = "a/b"', "mqtt.group_id: expected a Sparkplug id"),
        ('sparkplug = true\ngroup_id = "a+"', "mqtt.group_id: expected a Sparkplug id"),
        ('sparkplug = true\ngroup_id = ""', "mqtt.group_id: expected a Sparkplug id"),
        ('sparkplug = true\ngroup_id = "g"\nprimary_host_id = "#"',
         "mqtt.primary_host_id: expected a Sparkplug id"),
        ('group_id = "g"', "mqtt.group_id: needs sparkplug = true"),
        ('primary_host_id = "h"', "mqtt.primary_host_id: needs sparkplug = true"),
        ("state_topics = false", "mqtt.state_topics: with state_topics = false, [mqtt] publishes"),
        ('sparkplug = "yes"', "mqtt.sparkplug: expected"),
    ],
)  # fmt: skip
def test_a_bad_sparkplug_setting_is_one_line_naming_its_key(section: str, error: str) -> None:
    with pytest.raises(GatewayConfigError) as raised:
        _alias(section)
    assert error in str(raised.value)
    assert "\n" not in str(raised.value)


@pytest.mark.parametrize(
    ("section", "error"),
    [
        ("", "sparkplug.group_id: missing required key 'group_id'"),
        ('group_id = "a/b"', "sparkplug.group_id: expected a Sparkplug id"),
        ('group_id = "g"\nsparkplug = true', "sparkplug.sparkplug: unknown key"),
        ('group_id = "g"\ntls_key = "/etc/hostname"', "sparkplug.tls_key: tls_key needs tls_cert"),
        ('group_id = "g"\ntls_cert = "nowhere.pem"', "sparkplug.tls_cert: no such file"),
    ],
)
def test_a_bad_sparkplug_section_is_one_line_naming_its_key(section: str, error: str) -> None:
    with pytest.raises(GatewayConfigError) as raised:
        _section(section)
    assert error in str(raised.value)
    assert "\n" not in str(raised.value)
