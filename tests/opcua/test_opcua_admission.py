"""The admission's rules on their own (opcua/_admission.py): which CreateSession it refuses
and why, which session it closes and when. Sessions are plain objects here; the attack
tests (test_opcua_attacks.py) make them with asyncua over real sockets."""

from __future__ import annotations

from asyncua import ua
from waiting import wait_for

from sj300_async.gateway.opcua._admission import Admission, SessionLimits

TOO_MANY = ua.StatusCodes.BadTooManySessions
A1, A2, B1 = ("10.0.0.1", 1000), ("10.0.0.1", 1001), ("10.0.0.2", 1000)


def _admission(**limits: float) -> tuple[Admission, list[object]]:
    closed: list[object] = []
    given = {
        "sessions": 6,
        "max_connections_per_address": 3,
        "max_unactivated_per_address": 2,
        "activate_within_s": 60.0,
    } | limits
    return Admission(SessionLimits(**given), closed.append), closed  # type: ignore[arg-type]


def _create(admission: Admission, peer: tuple[str, int]) -> object | int:
    """A session for *peer*, or the status code refusing it."""
    status = admission.admit(peer)
    if status is not None:
        return status
    session = object()
    assert admission.created(session, peer, admitted=True) is None
    return session


async def test_each_limit_refuses_with_its_reason() -> None:
    admission, closed = _admission(max_unactivated_per_address=3)
    first, second = _create(admission, A1), _create(admission, A1)
    assert _create(admission, A1) == TOO_MANY  # the connection holds two
    third = _create(admission, A2)
    assert _create(admission, A2) == TOO_MANY  # the address: three in all
    assert admission.admit(B1, discovery=True) == ua.StatusCodes.BadSecurityPolicyRejected
    assert dict(admission.sessions_refused) == {"per_connection": 1, "per_address": 1,
                                                "discovery": 1}  # fmt: skip
    # Two of the address's three activated: its unactivated may be two again, but its
    # share is still three.
    admission.activated(first)
    admission.activated(second)
    assert _create(admission, A2) == TOO_MANY
    assert admission.sessions_refused["per_address"] == 2
    assert closed == []
    assert admission.unactivated == 1
    del third


async def test_the_unactivated_of_an_address_are_capped_below_its_share() -> None:
    admission, _ = _admission(max_connections_per_address=5)
    assert not isinstance(_create(admission, A1), int)
    assert not isinstance(_create(admission, A2), int)
    assert _create(admission, ("10.0.0.1", 1002)) == TOO_MANY
    assert admission.sessions_refused["unactivated_per_address"] == 1


async def test_a_newcomer_closes_the_oldest_unactivated_when_every_slot_is_taken() -> None:
    admission, closed = _admission(sessions=3)
    oldest, activated = _create(admission, A1), _create(admission, B1)
    admission.activated(activated)
    younger = _create(admission, ("10.0.0.3", 1))
    newcomer = _create(admission, ("10.0.0.4", 1))
    assert closed == [oldest]
    assert admission.sessions_refused["evicted"] == 1
    admission.activated(younger)
    admission.activated(newcomer)
    assert _create(admission, ("10.0.0.5", 1)) == TOO_MANY  # all activated: full
    assert admission.sessions_refused["full"] == 1


async def test_an_unactivated_session_is_closed_in_time_and_with_its_connection() -> None:
    admission, closed = _admission(activate_within_s=0.05)
    assert admission.connection_opened(A1)
    late = _create(admission, A1)
    await wait_for(lambda: closed == [late], "the session expired")
    assert admission.sessions_refused["expired"] == 1
    admission.closed(late)  # asyncua's close, heard back
    admission, closed = _admission()
    assert admission.connection_opened(A1)
    pending, kept = _create(admission, A1), _create(admission, A1)
    admission.activated(kept)
    admission.connection_closed(A1)
    assert closed == [pending]  # the activated one may outlive it (its subscriptions)
    assert admission.sessions == 1


async def test_connections_are_capped_per_address() -> None:
    admission, _ = _admission(max_connections_per_address=2)
    assert admission.connection_opened(A1)
    assert admission.connection_opened(A2)
    assert not admission.connection_opened(("10.0.0.1", 1002))
    assert admission.connection_opened(B1)
    admission.connection_closed(A1)
    assert admission.connection_opened(("10.0.0.1", 1003))
    assert admission.connections_refused["per_address"] == 1
    assert admission.connections == 3
