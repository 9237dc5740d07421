"""Our payloads as Eclipse Tahu reads them, Tahu's commands as we read them, and the section.

Tahu's JavaScript codec (sparkplug-payload) is the independent party: each
value the edge node encodes must decode there to the same value and type,
and each command form a host sends must decode here to the value it meant.
"""

from __future__ import annotations

import pytest

from sj300_async.gateway import GatewayConfigError, parse_config
from sj300_async.gateway.mqtt import MqttConfig
from sj300_async.gateway.sparkplug import (
    DATA_TYPES,
    MalformedPayload,
    MetricDef,
    Property,
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


def _mqtt(section: str) -> MqttConfig:
    text = f'[mqtt]\nurl = "mqtt://127.0.0.1"\n{section}\n[[lines]]\nurl = "sim://"\nnodes = "1"\n'
    config = parse_config(text, "gw.toml").northbounds["mqtt"]
    assert isinstance(config, MqttConfig)
    return config


def test_the_section_takes_sparkplug_with_its_group_and_host() -> None:
    config = _mqtt('sparkplug = true\ngroup_id = "Plant 1"\nprimary_host_id = "scada"')
    assert config.sparkplug is not None
    assert (config.sparkplug.group_id, config.sparkplug.primary_host_id) == ("Plant 1", "scada")
    assert config.state_topics
    assert _mqtt("").sparkplug is None


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
        ("state_topics = false", "mqtt.state_topics: with state_topics = false, set sparkplug"),
        ('sparkplug = "yes"', "mqtt.sparkplug: expected"),
    ],
)  # fmt: skip
def test_a_bad_sparkplug_setting_is_one_line_naming_its_key(section: str, error: str) -> None:
    with pytest.raises(GatewayConfigError) as raised:
        _mqtt(section)
    assert error in str(raised.value)
    assert "\n" not in str(raised.value)
