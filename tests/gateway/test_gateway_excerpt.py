"""What a client sent reaches logs, replies and the audit log only as a short escaped excerpt."""

from __future__ import annotations

import json
import logging
from pathlib import Path

import pytest

from sj300_async.gateway import (
    AuditLog,
    GatewayDrive,
    Lease,
    LineConfig,
    Refusal,
    WriteResult,
    excerpt,
)
from sj300_async.gateway.mqtt import parse_command
from sj300_async.profiles import get_profile


@pytest.mark.parametrize(
    ("text", "shown"),
    [
        pytest.param("25.5", "25.5", id="short"),
        pytest.param("x" * 64, "x" * 64, id="exactly-the-limit"),
        pytest.param("x" * 65, "x" * 48 + "…(65 characters)", id="one-over"),
        pytest.param("a\x1b[2J\nb", "a\\x1b[2J\\nb", id="unprintables-escaped"),
        pytest.param(b"run\xff", "run\ufffd", id="not-utf8"),
        pytest.param(b"9" * (1 << 20), "9" * 48 + "…(1048576 bytes)", id="a-mebibyte"),
        pytest.param("\x00" * 20, "\\x00" * 12 + "…(20 characters)", id="cut-between-escapes"),
        pytest.param("é" * 64, "é" * 64, id="characters-not-bytes"),
    ],
)
def test_excerpt(text: str | bytes, shown: str) -> None:
    assert excerpt(text) == shown
    assert len(excerpt(text)) <= 64


def test_a_refusal_quotes_no_more_than_an_excerpt() -> None:
    profile = get_profile("sj300")
    for what, payload in (("frequency_hz", b"x" * 4000), ("command", b"y" * 4000)):
        result = parse_command(profile, what, payload)
        assert isinstance(result, WriteResult)
        assert result.refusal is Refusal.MALFORMED
        assert len(result.detail) < 150, result.detail
    oversized = parse_command(profile, "lease", b"z" * 4097)  # any payload, but not any size
    assert isinstance(oversized, WriteResult)
    assert str(oversized) == "malformed: a command is at most 4096 bytes, got 4097: not read"


def test_the_audit_log_excerpts_every_text_it_is_given(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.INFO, "sj300_async.gateway.audit")
    line = LineConfig(name="hall", url="sim://", protocol="sj300", nodes=(1,))
    drive = GatewayDrive(line, 1, get_profile("sj300"), Lease(5.0))
    audit = AuditLog(tmp_path / "audit.log")
    huge = "\x1b" + "q" * 100_000
    audit.write("mqtt", drive, "mqtt " + huge, huge, huge, WriteResult(Refusal.MALFORMED, huge))
    audit.record("10.0.0.9", drive, "register 1002", None, [0, 7], "ok")
    audit.close()
    first, second = (json.loads(text) for text in (tmp_path / "audit.log").read_text().splitlines())
    assert first["new"] == first["old"] == excerpt(huge)
    assert first["what"] == excerpt("mqtt " + huge)
    assert len(first["detail"]) == 256
    assert second["new"] == [0, 7]  # a Modbus write's registers stay a JSON array
    assert max(len(r.getMessage()) for r in caplog.records) < 600
    assert audit.counts == {"malformed": 1, "ok": 1}
