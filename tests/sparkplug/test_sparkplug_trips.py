"""A trip record on Sparkplug (issue 45): each device's ``Trip Record/Code`` and
``Trip Record/Id``, born null, sent in a DDATA once the gateway keeps a record, as Tahu's
codec decodes what mosquitto delivered."""

from __future__ import annotations

import asyncio

from mqtt_broker import Broker

from .conftest import SimLine, running_gateway, spb_toml
from .host import Codec, host
from .test_sparkplug_lifecycle import births, current, names

#: The recorder of a short window: the record a second after the trip.
RECORDER = "\n[recorder]\nbefore_s = 1\nafter_s = 0.5\n"


async def test_a_trip_record_is_a_ddata_of_its_code_and_id(
    sim_line: SimLine, broker: Broker, tahu: Codec
) -> None:
    text = spb_toml(sim_line.url, broker) + RECORDER
    async with host(broker, tahu) as h, running_gateway(text) as gateway:
        await h.until(lambda m: m.kind == "DBIRTH", "a birth per drive", count=4)
        born = names(births(h, "hall-2")[0])
        assert sim_line.sim.drives[2].trip(7, now=asyncio.get_running_loop().time())
        await h.until(
            lambda m: m.kind == "DDATA" and bool(current(h, "hall-2").get("Trip Record/Id")),
            "the record in a DDATA",
        )
        assert gateway.trip_records is not None
        summary = gateway.trip_records.summaries()[0]
    assert not h.undecodable
    assert born["Trip Record/Code"]["type"] == born["Trip Record/Id"]["type"] == "String"
    assert born["Trip Record/Code"].get("value") is None
    values = current(h, "hall-2")
    assert (values["Trip Record/Code"], values["Trip Record/Id"]) == ("E07", summary.id)
    assert current(h, "hall-1").get("Trip Record/Id") is None  # another drive's is its own
