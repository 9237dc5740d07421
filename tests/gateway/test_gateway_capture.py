"""``sj300 gateway --capture``: every line's frames in one pcapng, an interface per line."""

from __future__ import annotations

import textwrap
from pathlib import Path

from waiting import wait_for

from sj300_async.gateway import Gateway, parse_config
from sj300_async.wire._pcapng import PacketDirection, read_pcapng


async def test_the_gateway_captures_each_line_on_its_own_interface(tmp_path: Path) -> None:
    config = parse_config(
        textwrap.dedent(
            """
            [[lines]]
            name = "hall"
            url = "sim://?nodes=1-2&baudrate=19200"
            nodes = "1-2"
            interval_s = 0.05
            [[lines]]
            name = "pumps"
            url = "sim://?protocol=fr700&nodes=3"
            protocol = "fr700"
            nodes = "3"
            interval_s = 0.05
            """
        ),
        "test.toml",
    )
    path = tmp_path / "plant.pcapng"
    async with Gateway(config, capture=str(path)) as gateway:
        await wait_for(
            lambda: all(drive.readings.online for drive in gateway.drives),
            "every drive polled",
        )
    capture = read_pcapng(path.read_bytes())
    assert [(i.linktype, i.description) for i in capture.interfaces] == [
        (147, "sj300 19200 8N1"),
        (148, "fr700 instant"),
    ]
    for number, nodes in ((0, {b"01", b"02"}), (1, {b"03"})):
        written = [
            p.data
            for p in capture.packets
            if p.interface == number and p.direction is PacketDirection.OUTBOUND
        ]
        assert {frame[1:3] for frame in written} == nodes
        assert any(
            p.interface == number and p.direction is PacketDirection.INBOUND
            for p in capture.packets
        )
