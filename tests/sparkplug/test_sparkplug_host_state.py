"""The primary host's STATE read, sans-IO: the order of timestamps, and what changes nothing.

The edge node's session (tests/sparkplug/test_sparkplug_host.py) acts on
these words against a real broker; here each rule alone, with the reason a
STATE that changes nothing is counted under.
"""

from __future__ import annotations

import json

from sj300_async.gateway.sparkplug._host import MAX_STATE_BYTES, HostWord, PrimaryHost, Unread


def _state(online: object, timestamp: object) -> bytes:
    return json.dumps({"online": online, "timestamp": timestamp}).encode()


def _read(host: PrimaryHost, payload: bytes) -> HostWord | Unread:
    return host.read(payload, len(payload))


def test_online_then_offline_in_timestamp_order() -> None:
    host = PrimaryHost("scada", "spBv1.0")
    assert host.topic == "spBv1.0/STATE/scada"
    assert host.online is None
    assert _read(host, _state(True, 10)) == HostWord(online=True, again=False)
    assert _read(host, _state(True, 11)) == HostWord(online=True, again=True)
    assert _read(host, _state(False, 12)) == HostWord(online=False, again=False)
    assert host.online is False


def test_an_older_state_is_stale_even_on_a_new_connection() -> None:
    host = PrimaryHost("scada", "spBv1.0")
    _read(host, _state(True, 100))
    host.forget()  # a new connection: the word is gone, the order stays
    assert host.online is None
    assert _read(host, _state(False, 99)) == Unread("stale_state", "STATE of 99 after one of 100")
    assert host.online is None
    assert _read(host, _state(True, 100)) == HostWord(online=True, again=False)


def test_what_is_no_state_changes_nothing() -> None:
    host = PrimaryHost("scada", "spBv1.0")
    for payload in (
        b"not json",
        b"[" * 1000,  # deep: the parser may recurse out (within the size read)
        _state("yes", 1),
        _state(True, True),
        _state(True, 1.5),
        json.dumps({"online": True}).encode(),
    ):
        word = _read(host, payload)
        assert isinstance(word, Unread)
        assert word.reason == "malformed", payload[:20]
    assert host.read(b"", MAX_STATE_BYTES + 1) == Unread(
        "oversized", f"STATE: {MAX_STATE_BYTES + 1} bytes, not read"
    )
    assert host.online is None
