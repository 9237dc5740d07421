"""answers(request, reply): which reply answers which request (docs: sj300.md, "Commands")."""

from __future__ import annotations

import pytest

from sj300_async import NakCode
from sj300_async.sj300 import (
    BROADCAST,
    AckDataReply,
    AckReply,
    DataReply,
    NakReply,
    Reply,
    Request,
    answers,
    requests,
)

NODE = 7

ACK_COMMANDS = [
    requests.run(NODE, 1),
    requests.set_frequency(NODE, 5.0),
    requests.set_terminals(NODE, 1),
    requests.write_parameter_raw(NODE, "C078", 40),
    requests.initialize(NODE),
    requests.store(NODE),
    requests.recalculate(NODE),
]
SHAPED: list[tuple[Request, Reply]] = [
    (requests.read_parameter(NODE, "A004"), AckDataReply(NODE, b"00000500")),
    (requests.can_store(NODE), AckDataReply(NODE, b"01")),
    (requests.read_status(NODE), DataReply(NODE, b"03010300")),
    (requests.read_monitor(NODE), DataReply(NODE, b"0" * 104)),
    (requests.read_trip_history(NODE), DataReply(NODE, b"0" * 440)),
]
ALL_REQUESTS = ACK_COMMANDS + [r for r, _ in SHAPED]
ALL_REPLIES: list[Reply] = [AckReply(NODE), *(reply for _, reply in SHAPED)]


@pytest.mark.parametrize("request_", ACK_COMMANDS, ids=lambda r: r.command.name)
def test_ack_answers_commands_that_get_ack(request_: Request) -> None:
    assert answers(request_, AckReply(NODE))
    assert not answers(request_, AckReply(NODE + 1))


@pytest.mark.parametrize(("request_", "reply"), SHAPED, ids=[r.command.name for r, _ in SHAPED])
def test_each_read_is_answered_by_its_own_shape_only(request_: Request, reply: Reply) -> None:
    for candidate in ALL_REPLIES:
        assert answers(request_, candidate) is (candidate == reply), candidate


@pytest.mark.parametrize("request_", ALL_REQUESTS, ids=lambda r: r.command.name)
def test_nak_from_the_node_answers_anything(request_: Request) -> None:
    assert answers(request_, NakReply(NODE, NakCode.ABNORMAL_PARAMETER))
    assert answers(request_, NakReply(NODE, NakCode(42)))
    assert not answers(request_, NakReply(NODE + 1, NakCode.CHECKSUM))


@pytest.mark.parametrize("request_", ALL_REQUESTS, ids=lambda r: r.command.name)
def test_reply_from_another_node_answers_nothing(request_: Request) -> None:
    for node in (1, NODE - 1, NODE + 1, 32):
        for reply in (AckReply(node), DataReply(node, b"03010300"), AckDataReply(node, b"01")):
            assert not answers(request_, reply)


@pytest.mark.parametrize(
    "request_",
    [
        requests.run(BROADCAST, 1),
        requests.store(BROADCAST),
        requests.write_parameter_raw(BROADCAST, "B084", 1),
    ],
    ids=lambda r: r.command.name,
)
def test_a_broadcast_has_no_answer(request_: Request) -> None:
    for node in range(1, 33):
        assert not answers(request_, AckReply(node))
        assert not answers(request_, NakReply(node, NakCode.CHECKSUM))
