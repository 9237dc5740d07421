"""One-shot calls: open a bus, command a drive, read it back, close.

.venv/bin/python examples/one_shot.py                      # the in-memory simulator
.venv/bin/python examples/one_shot.py tcp://127.0.0.1:4001 # a device server or `sj300 simulate`

Ctrl-C stops the drive and exits with status 130, without a traceback.
"""

from __future__ import annotations

import asyncio
import sys

import sj300_async as sj


async def main(url: str) -> None:
    async with sj.open_bus(url, timeout=0.5) as bus:
        drive = bus.drive(1)
        await drive.write_parameter("F002", 2.0)  # accelerate 0 -> max in 2 s
        await drive.set_frequency(30.0)
        await drive.run_forward()
        print("node 1: running forward to 30 Hz", flush=True)
        try:
            await asyncio.sleep(0.5)
            monitor = await drive.read_monitor()
            status = await drive.read_status()
            print(
                f"node 1: {status.a.name}, {monitor.output_frequency_hz:.2f} Hz, "
                f"{monitor.output_current_a:.1f} A"
            )
        finally:  # also on Ctrl-C: a motor is not left running
            await drive.stop()
        try:
            await bus.drive(1).read_parameter_raw("Z999")
        except sj.LocalProtocolError as exc:
            print(f"refused before sending: {exc}")
        stats = bus.stats.transactions.snapshot()
        mean = "-" if stats.latency_mean_s is None else f"{stats.latency_mean_s * 1000:.1f} ms"
        print(
            f"bus statistics: requests {stats.requests}, replies {stats.replies}, "
            f"time-outs {stats.timeouts}, retries {stats.retries}, "
            f"NAKs {sum(stats.naks.values())}, mean round trip {mean}"
        )


if __name__ == "__main__":
    try:
        asyncio.run(main(sys.argv[1] if len(sys.argv) > 1 else "sim://?nodes=1-4"))
    except KeyboardInterrupt:  # Ctrl-C: asyncio.run has cancelled main(), which stopped the drive
        sys.exit(130)
