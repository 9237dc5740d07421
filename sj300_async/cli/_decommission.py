"""``sj300 gateway --decommission``: clear what a gateway id left retained on its MQTT broker.

A gateway taken out of service leaves its retained states, availabilities
and Home Assistant configs on the broker: Home Assistant would show its
drives, stale, for ever. This connects to the ``[mqtt]`` broker of the
configuration (the same URL, credentials and TLS), clears every retained
topic of the configuration's gateway id (``sj300_async.gateway.mqtt``'s
sweep with nothing kept) and says what it cleared in one line. Another
gateway's topics are never read: the gateway id is a whole topic level.
Run it with the gateway stopped, or it publishes everything again.
"""

from __future__ import annotations

import asyncio

from ..gateway import GatewayConfig
from ._errors import CliError

__all__ = ["decommission"]


def decommission(config: GatewayConfig) -> int:
    """Clear the gateway id's retained topics on the ``[mqtt]`` broker; 0 when done."""
    from ..gateway.mqtt import MqttConfig, SweepRefused, Topics, sweep
    from ..gateway.mqttlink.client import MqttError

    mqtt = config.northbounds.get("mqtt")
    if not isinstance(mqtt, MqttConfig):
        raise CliError("--decommission clears what [mqtt] published: the configuration has none")
    topics = Topics(config.gateway_id, mqtt.prefix)
    try:
        swept = asyncio.run(sweep(mqtt, topics, None))
    except (SweepRefused, MqttError, OSError, TimeoutError) as exc:
        raise CliError(f"{mqtt.url}: {exc or type(exc).__name__}: nothing cleared") from None
    drives = len(swept.drives)
    print(
        f"cleared {swept.topics} retained topics of gateway {config.gateway_id} on {mqtt.url} "
        f"({drives} drive{'s' * (drives != 1)})"
    )
    return 0
