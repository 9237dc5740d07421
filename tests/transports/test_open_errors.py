"""Opening a line that is not there: the error says why once, and what was probably meant.

Issue 27, item 4: ``--url 127.0.0.1:4001`` (no scheme) is a serial port
path; the error showed pyserial's errno twice and did not say that a TCP
bridge needs ``tcp://``.
"""

from __future__ import annotations

from pathlib import Path

import pytest

import sj300_async as sj


async def _open_error(url: str) -> str:
    with pytest.raises(sj.TransportError) as caught:
        async with sj.open_bus(url):
            pass
    return str(caught.value)


@pytest.mark.parametrize(
    "text", ["127.0.0.1:4001", "bridge.local:4001", "localhost:502", "[::1]:4001", "[fe80::1]:4001"]
)
async def test_host_port_without_a_scheme_suggests_tcp(text: str) -> None:
    message = await _open_error(text)
    assert message.startswith(f"cannot open serial port {text}: "), message
    assert message.endswith(f"for a TCP bridge use tcp://{text}"), message


async def test_a_missing_device_path_names_the_errno_once(tmp_path: Path) -> None:
    device = f"{tmp_path}/ttyUSB9"
    message = await _open_error(device)
    assert message == f"cannot open serial port {device}: No such file or directory (errno 2)"


@pytest.mark.parametrize("name", ["COM3", "ttyUSB9:1"])
async def test_a_serial_name_gets_no_tcp_hint(tmp_path: Path, name: str) -> None:
    # "ttyUSB9:1" is no HOST:PORT only by being relative here: a path with a
    # slash never gets the hint, whatever its colons.
    device = f"{tmp_path}/{name}"
    message = await _open_error(device)
    assert "tcp://" not in message, message
    assert message.count("errno") == 1, message


async def test_a_serial_url_still_opens_a_serial_port(tmp_path: Path) -> None:
    message = await _open_error(f"serial://{tmp_path}/ttyUSB9?baudrate=9600")
    assert message.startswith(f"cannot open serial port {tmp_path}/ttyUSB9: "), message
    assert "tcp://" not in message
