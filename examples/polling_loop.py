"""A polling loop: keep the state of several drives current while sending commands.

    .venv/bin/python examples/polling_loop.py [URL] [--duration SECONDS]

The poller reads status and monitor data of drives 1..4 every 0.2 s; the
main task changes set points in between. Each command waits for at most
the one transaction on the line, never for a whole polling cycle. Ctrl-C
stops every drive and exits with status 130, without a traceback.
"""

from __future__ import annotations

import argparse
import asyncio
import sys

import sj300_async as sj


def show(sample: sj.Sample) -> None:
    if sample.error is not None:
        print(f"node {sample.node:02d}: {'online' if sample.online else 'OFFLINE'} {sample.error}")
    elif sample.monitor is not None and sample.status is not None:
        m = sample.monitor
        print(
            f"node {sample.node:02d}: {sample.status.a.name:<8} {m.output_frequency_hz:6.2f} Hz "
            f"{m.output_current_a:5.1f} A {m.direction.name}"
        )


async def main(url: str, duration: float) -> None:
    async with sj.open_bus(url) as bus:
        poller = sj.Poller(interval_s=0.2, reads=("status", "monitor"))
        poller.add(bus, [1, 2, 3, 4])
        poller.on_sample(show)
        async with poller:
            try:
                for node in (1, 2, 3, 4):
                    await bus.drive(node).write_parameter("F002", 1.0)  # 0 -> max in 1 s
                    await bus.drive(node).write_parameter("F003", 1.0)
                    await bus.drive(node).set_frequency(10.0 * node)
                    await bus.drive(node).run_forward()
                await asyncio.sleep(duration / 2)
                await bus.drive(2).run_reverse()
                await asyncio.sleep(duration / 2)
            finally:  # also on Ctrl-C: no motor is left running
                await bus.broadcast.stop()
        for node in (1, 2, 3, 4):
            health = poller.health(bus, node)
            print(f"node {node:02d}: {health.polls} polls, {health.failures} failures")


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("url", nargs="?", default="sim://?nodes=1-4")
    parser.add_argument("--duration", type=float, default=5.0)
    args = parser.parse_args()
    try:
        asyncio.run(main(args.url, args.duration))
    except KeyboardInterrupt:  # Ctrl-C: asyncio.run has cancelled main(), which stopped the drives
        sys.exit(130)
