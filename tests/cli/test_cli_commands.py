"""Every bus subcommand through the real entry point, on sim:// and over TCP: text and JSON."""

from __future__ import annotations

import asyncio

from sj300_async import StatusA
from sj300_async.simulator import RunState

from .clirun import TcpSim, sj300, sj300_on_terminal


async def test_status_out_of_the_box_uses_the_in_memory_simulator() -> None:
    result = await sj300("status")
    assert result.code == 0, result.err
    assert result.out.splitlines()[0] == "node 01"
    assert "output frequency      0.00 Hz" in result.out
    # Status A 02 ("on stopping" in the manual) is the stopped state: worded so.
    assert "state (A)             stopped (02)" in result.out
    # The setpoint beside the output frequency, as a SCADA screen shows them.
    assert "set frequency         0.00 Hz\noutput frequency      0.00 Hz" in result.out


async def test_status_json_uses_the_dataclass_field_names() -> None:
    data = (await sj300("status", "-n", "3", "--json")).json()
    assert data["node"] == 3
    assert data["status"] == {"a": "STOPPING", "b": "STOPPED", "c": "STOP"}
    assert data["set_frequency_hz"] == 0.0
    monitor = data["monitor"]
    assert monitor["output_frequency_hz"] == 0.0
    assert monitor["direction"] == "STOP"
    assert monitor["input_terminals"] == 0  # a bit field stays a number
    assert set(monitor) >= {"output_current_a", "output_voltage_v", "power_kw", "run_time_h"}


async def test_read_scales_by_the_catalogue() -> None:
    result, raw = await asyncio.gather(
        sj300("read", "F002", "a004", "C078"), sj300("read", "F002", "--raw")
    )
    assert result.code == 0, result.err
    lines = result.out.splitlines()
    assert lines[0].split() == ["code", "name", "value"]
    assert lines[1].split() == ["F002", "acceleration", "time", "1", "30.00", "s"]
    assert lines[2].split() == ["A004", "maximum", "frequency", "50.0", "Hz"]
    assert lines[3].split()[-2:] == ["0", "ms"]
    assert raw.out.splitlines()[1].split()[-1] == "3000"


async def test_read_json_has_value_and_raw() -> None:
    data = (await sj300("read", "F002", "A004", "--json", "--sim")).json()
    assert data == {
        "node": 1,
        "parameters": [
            {
                "code": "F002",
                "name": "acceleration time 1",
                "value": 30.0,
                "unit": "s",
                "raw": 3000,
            },
            {"code": "A004", "name": "maximum frequency", "value": 50.0, "unit": "Hz", "raw": 500},
        ],
    }


async def test_write_persists_on_a_tcp_simulator(tcp_sim: TcpSim) -> None:
    result = await sj300("write", "F002", "12.5", "--url", tcp_sim.url, "-n", "2")
    assert result.code == 0, result.err
    assert result.out == "node 02 F002 acceleration time 1: 30.00 s -> 12.50 s\n"
    assert tcp_sim.bus.drives[2].parameters["F002"] == 1250
    data = (await sj300("write", "F003", "700", "--raw", "--json", "--url", tcp_sim.url)).json()
    assert data["old_raw"] == 3000
    assert (data["raw"], data["value"], data["unit"]) == (700, 7.0, "s")
    assert data["stored"] is False
    # The next command sees it: state lives in the TCP simulator, not in the command.
    again = await sj300("read", "F003", "--json", "--url", tcp_sim.url)
    assert again.json()["parameters"][0]["raw"] == 700


async def test_write_store_reaches_eeprom(tcp_sim: TcpSim) -> None:
    result = await sj300("write", "C078", "20", "--store", "--url", tcp_sim.url)
    assert result.code == 0, result.err
    assert result.out.endswith("0 ms -> 20 ms (stored)\n")
    assert tcp_sim.bus.drives[1].stored_parameters["C078"] == 20


async def test_freq_run_status_stop_over_tcp(tcp_sim: TcpSim) -> None:
    url = ("--url", tcp_sim.url)
    assert (await sj300("freq", "30", *url)).out == "node 01: frequency set to 30.00 Hz\n"
    run = await sj300("run", "forward", "--json", *url)
    assert run.json() == {"node": 1, "direction": "FORWARD"}
    loop = asyncio.get_running_loop()
    assert tcp_sim.bus.drives[1].state(loop.time()) is RunState.ACCELERATING
    status = (await sj300("status", "--json", *url)).json()
    assert status["status"]["a"] == "RUNNING"
    assert status["monitor"]["direction"] == "FORWARD"
    assert status["monitor"]["output_frequency_hz"] > 0
    stop = await sj300("stop", *url)
    assert stop.out == "node 01: stop\n"
    assert tcp_sim.bus.drives[1].state(loop.time()) is RunState.DECELERATING


async def test_run_reverse_and_freq_json(tcp_sim: TcpSim) -> None:
    url = ("--url", tcp_sim.url, "-n", "4")
    assert (await sj300("freq", "12.34", "--json", *url)).json() == {
        "node": 4,
        "frequency_hz": 12.34,
    }
    assert (await sj300("run", "reverse", *url)).out == "node 04: run reverse\n"
    assert tcp_sim.bus.drives[4].parameters["F001"] == 1234
    status = tcp_sim.bus.drives[4].status(asyncio.get_running_loop().time())
    assert status.a == StatusA.RUNNING


async def test_stop_all_broadcasts(tcp_sim: TcpSim) -> None:
    runs = [sj300("run", "forward", "-n", node, "--url", tcp_sim.url) for node in ("1", "2")]
    assert [r.code for r in await asyncio.gather(*runs)] == [0, 0]
    result = await sj300("stop", "--all", "--json", "--url", tcp_sim.url)
    assert result.json() == {"node": None, "broadcast": True}
    now = asyncio.get_running_loop().time()
    for node in (1, 2):
        assert tcp_sim.bus.drives[node].state(now) in (RunState.DECELERATING, RunState.STOPPED)
    plain = await sj300("stop", "--all", "--url", tcp_sim.url)
    assert plain.out == "all drives: stop (broadcast)\n"


async def test_trips_shows_the_history(tcp_sim: TcpSim) -> None:
    now = asyncio.get_running_loop().time()
    empty = await sj300("trips", "-n", "2", "--url", tcp_sim.url)
    assert empty.out == "node 02: 0 trip(s) in total, none recorded\n"
    tcp_sim.bus.drives[2].trip(7, now=now)
    tcp_sim.bus.drives[2].reset(now)
    tcp_sim.bus.drives[2].trip(21, now=now)
    result = await sj300("trips", "-n", "2", "--url", tcp_sim.url)
    assert result.code == 0, result.err
    lines = result.out.splitlines()
    assert lines[0] == "node 02: 2 trip(s) in total, newest first"
    assert lines[1].split()[:2] == ["#", "trip"]
    assert lines[2].split()[:2] == ["1", "E21"]
    assert "THERMAL" in lines[2]
    assert lines[3].split()[:2] == ["2", "E07"]
    data = (await sj300("trips", "-n", "2", "--json", "--url", tcp_sim.url)).json()
    assert data["node"] == 2
    assert data["total_count"] == 2
    assert [r["error_code"] for r in data["records"]] == ["E21", "E07"]
    assert data["records"][0]["trip_factor"] == 21
    assert data["records"][0]["status_b"] == 16  # THERMAL, a bit field as its number
    assert data["records"][0]["status_c"] in {"STOPPING", "RESET"}


async def test_scan_lists_the_nodes_that_answer(tcp_sim: TcpSim) -> None:
    result, as_json = await asyncio.gather(
        sj300("scan", "--nodes", "1-6", "--url", tcp_sim.url),
        sj300("scan", "--nodes", "3-5", "--json", "--url", tcp_sim.url),
    )
    assert result.code == 0, result.err
    assert result.out == "nodes answering: 1-4 (4 of 6)\n"
    assert result.err.splitlines() == [
        *(f"node {n:02d}: answers" for n in range(1, 5)),
        "node 05: no answer",
        "node 06: no answer",
    ]
    assert as_json.json() == {"scanned": [3, 4, 5], "answering": [3, 4]}


async def test_scan_finding_nobody_exits_1() -> None:
    result = await sj300("scan", "--nodes", "20-21", "--url", "sim://?nodes=1")
    assert result.code == 1
    assert result.out == "no node answers (tried 20-21)\n"
    assert "Traceback" not in result.err


async def test_the_url_comes_from_sj300_url(tcp_sim: TcpSim) -> None:
    await sj300("freq", "7", "--url", tcp_sim.url)
    result = await sj300("read", "F001", "--json", env_url=tcp_sim.url)
    assert result.json()["parameters"][0]["value"] == 7.0
    # --url wins over the environment.
    fresh = await sj300("read", "F001", "--json", "--url", "sim://", env_url=tcp_sim.url)
    assert fresh.json()["parameters"][0]["value"] == 0.0


async def test_line_settings_apply_to_a_paced_simulator() -> None:
    result = await sj300(
        "read", "C078", "--url", "sim://?nodes=1&pace=1", "--baud", "9600", "--parity", "e"
    )
    assert result.code == 0, result.err


async def test_an_unpaced_simulator_on_a_line_with_a_speed_answers_plausibly() -> None:
    # Unpaced, sim:// answers at once; on a line with a speed the host's
    # plausibility floor would refuse that, so the simulator waits for physics.
    result = await sj300("read", "C078", "--url", "sim://?nodes=1", "--baud", "9600")
    assert result.code == 0, result.err
    result = await sj300("status", "--url", "sim://?nodes=1&baudrate=19200", "--json")
    assert result.code == 0, result.err
    assert result.json()["node"] == 1


async def test_terminal_output_is_a_rich_table() -> None:
    result = await sj300_on_terminal("read", "F002", "A004")
    assert result.code == 0, result.out
    assert "─" in result.out  # a rich table rule
    assert "acceleration time 1" in result.out
    assert "30.00 s" in result.out


async def test_scan_on_a_terminal_shows_a_progress_bar_then_the_result() -> None:
    result = await sj300_on_terminal("scan", "--nodes", "1-3", "--url", "sim://?nodes=1-2")
    assert result.code == 0, result.out
    assert "scanning node" in result.out
    assert "nodes answering: 1-2 (2 of 3)" in result.out
