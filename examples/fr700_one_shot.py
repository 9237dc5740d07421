"""One-shot calls to a Mitsubishi FR-700 drive: the same stack, the computer-link protocol.

.venv/bin/python examples/fr700_one_shot.py                      # the in-memory FR-700 simulator
.venv/bin/python examples/fr700_one_shot.py tcp://127.0.0.1:4002 # `sj300 simulate --protocol fr700`

Ctrl-C stops the drive and exits with status 130, without a traceback.
"""

from __future__ import annotations

import asyncio
import sys

import sj300_async as sj
from sj300_async.fr700 import Fr700NakCode


async def main(url: str) -> None:
    async with sj.open_bus(url, protocol="fr700", timeout=0.5) as bus:
        drive = bus.drive(0)  # FR-700 stations are 0..31
        await drive.write_parameter(7, 2.0)  # Pr.7 acceleration time in s (raw 20)
        await drive.set_frequency(30.0)  # HED: RAM only
        await drive.run_forward()  # HFA H02
        print("station 0: running forward to 30 Hz", flush=True)
        try:
            await asyncio.sleep(0.5)
            status = await drive.read_status()  # H7A
            monitor = await drive.read_monitor()  # H6F, H70, H71
            print(
                f"station 0: {'running' if status.running else 'stopped'}, "
                f"{monitor.output_frequency_hz:.2f} Hz, {monitor.output_current_a:.2f} A, "
                f"{monitor.output_voltage_v:.1f} V"
            )
        finally:  # also on Ctrl-C: a motor is not left running
            await drive.stop()
        try:
            await drive.set_frequency(400.0)  # above Pr.1, the maximum frequency
        except sj.NakError as exc:  # exc.code is an Fr700NakCode
            kind = "data range" if exc.code == Fr700NakCode.DATA_RANGE else "other"
            print(f"refused by the drive ({kind}): {exc}")
        stats = bus.stats.transactions.snapshot()
        mean = "-" if stats.latency_mean_s is None else f"{stats.latency_mean_s * 1000:.1f} ms"
        print(
            f"bus statistics: requests {stats.requests}, replies {stats.replies}, "
            f"time-outs {stats.timeouts}, retries {stats.retries}, "
            f"NAKs {sum(stats.naks.values())}, mean round trip {mean}"
        )


if __name__ == "__main__":
    try:
        asyncio.run(main(sys.argv[1] if len(sys.argv) > 1 else "sim://?protocol=fr700&nodes=0-3"))
    except KeyboardInterrupt:  # Ctrl-C: asyncio.run has cancelled main(), which stopped the drive
        sys.exit(130)
