"""The running gateway's metrics and health: what a Prometheus scrape of a live gateway shows."""

from __future__ import annotations

from prometheus_client.samples import Sample
from waiting import wait_for

from .conftest import SimLine, gateway_toml, metrics_port, modbus_client, running_gateway
from .test_gateway_metrics import fetch, scrape


def _value(samples: list[Sample], name: str, **labels: str) -> float:
    found = [s.value for s in samples if s.name == name and s.labels == labels]
    assert len(found) == 1, (name, labels, found)
    return found[0]


async def test_a_scrape_shows_lines_drives_and_clients(sim_line: SimLine) -> None:
    text = gateway_toml(sim_line.url, extra='[metrics]\nlisten = "127.0.0.1:0"\n')
    sim_line.sim.drives[2].set_parameter("F001", 1250)
    async with running_gateway(text) as gateway:
        port = metrics_port(gateway)
        drives = gateway.drives
        await wait_for(
            lambda: all(d.readings.last_ok is not None for d in drives), "a first sample"
        )
        async with modbus_client(gateway) as client:
            for _ in range(3):
                assert not (await client.read_holding_registers(0, count=4, device_id=2)).isError()
            assert (await client.read_holding_registers(5000, device_id=2)).isError()
        samples = await scrape(port)
        bus = gateway.lines[0].bus
        assert _value(samples, "sj300_line_up", line="hall") == 1
        assert _value(samples, "sj300_line_requests_total", line="hall") >= 4
        assert _value(samples, "sj300_drive_online", line="hall", node="2") == 1
        assert _value(samples, "sj300_drive_output_frequency_hertz", line="hall", node="2") == 0
        assert _value(samples, "sj300_modbus_requests_total", client="127.0.0.1") == 4
        assert _value(samples, "sj300_modbus_exceptions_total", client="127.0.0.1", code="2") == 1
        assert bus.stats.transactions.requests >= _value(
            samples, "sj300_line_requests_total", line="hall"
        )
        healthy = await fetch(port, "/healthz")
        assert healthy.status == 200
        # The line goes away (the bridge is switched off): the health check says which.
        sim_line.server.close()
        await wait_for(lambda: not bus.connected, "the link down")
        down = await fetch(port, "/healthz")
        assert down.status == 503
        assert down.body == b"line hall: link down\n"
