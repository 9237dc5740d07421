"""The passive sniffer's judgement (:class:`LineSniffer`, sans-IO), on streams built by the library.

Every frame here comes from the library's own encoders (the request
builders, ``encode_reply``, FR-700's codec), fed at explicit times: pairing
and latency, the time-out the sniffer judges by, each anomaly kind, and the
property that the chunking of a stream never changes what the sniffer
reports when the chunks are fed at the same times.
"""

from __future__ import annotations

import itertools
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sj300_async import BusTiming, LineSettings
from sj300_async import fr700 as fr
from sj300_async import sj300 as sj3
from sj300_async.bus._sniffer import Anomaly, LineSniffer, SniffedFrame, Unanswered
from sj300_async.fr700 import requests as frq
from sj300_async.simulator._faults import corrupt as sj300_corrupt
from sj300_async.simulator.fr700._bus import corrupt as fr700_corrupt
from sj300_async.sj300 import requests as rq
from sj300_async.wire._frames import FrameRole

LINE = LineSettings(19200)
TIMING = BusTiming()
SJ = sj3.SJ300_DIALECT
FR = fr.Fr700Dialect()
PROPERTY = settings(max_examples=150, deadline=None)

Report = SniffedFrame | Unanswered


# -- the streams' frames -------------------------------------------------------------------


def status_reply(node: int, data: bytes = b"02000100") -> bytes:
    return sj3.encode_reply(sj3.DataReply(node, data))


def ack(node: int) -> bytes:
    return sj3.encode_reply(sj3.AckReply(node))


def value_reply(node: int, raw: int) -> bytes:
    return sj3.encode_reply(sj3.AckDataReply(node, b"%08d" % raw))


def monitor_reply(node: int) -> bytes:
    return sj3.encode_reply(sj3.DataReply(node, b"0" * 104))


def nak(node: int, code: sj3.NakCode = sj3.NakCode.CHECKSUM) -> bytes:
    return sj3.encode_reply(sj3.NakReply(node, code))


def sj300_frame(body: bytes) -> bytes:
    """STX body BCC CR, with a correct BCC whatever the body."""
    return b"\x02" + body + sj3.bcc(body) + b"\r"


#: A reply-shaped frame whose BCC is right but whose length fits no reply: broken, not bad check.
BAD_LENGTH = sj300_frame(b"01\x06XYZ")


class Tape:
    """A sniffer and everything it reported, fed at explicit times."""

    def __init__(
        self, dialect: Any = SJ, timing: BusTiming = TIMING, line: LineSettings = LINE
    ) -> None:
        self.sniffer = LineSniffer(dialect, line, timing)
        self.reports: list[Report] = []

    def feed(self, data: bytes, now: float) -> list[Report]:
        new = self.sniffer.feed(data, now)
        self.reports += new
        return new

    def one(self, data: bytes, now: float) -> SniffedFrame:
        """Feed *data*, which completes exactly one frame and nothing else."""
        new = self.feed(data, now)
        assert len(new) == 1, new
        assert isinstance(new[0], SniffedFrame), new
        return new[0]

    def tick(self, now: float) -> list[Report]:
        new = self.sniffer.tick(now)
        self.reports += new
        return new

    def flush(self, now: float) -> list[Report]:
        new = self.sniffer.flush(now)
        self.reports += new
        return new

    def flagged(self) -> Counter[Anomaly]:
        return Counter(a for report in self.reports for a in report.anomalies)


def timeout_of(request: Any, dialect: Any = SJ, timing: BusTiming = TIMING) -> float:
    """The host's response time-out of *request* (what the sniffer judges by)."""
    return timing.response_timeout(
        request, LINE, dialect.processing_s(request), dialect.reply_frame_length(request)
    )


def deadline_of(request: Any, heard_at: float, **kwargs: Any) -> float:
    """The sniffer's deadline: counted from the request's first byte, heard whole at *heard_at*."""
    return heard_at - LINE.wire_time_s(len(request.frame)) + timeout_of(request, **kwargs)


# -- pairing and latency -------------------------------------------------------------------


def test_a_reply_is_paired_with_its_request_and_its_latency_measured() -> None:
    tape = Tape()
    request = tape.one(rq.read_status(1).frame, 10.0)
    assert request.frame.role is FrameRole.REQUEST
    assert request.frame.message == rq.read_status(1)
    assert (request.number, request.answers, request.latency_s, request.anomalies) == (
        1,
        None,
        None,
        (),
    )
    reply = tape.one(status_reply(1), 10.0125)
    assert reply.frame.role is FrameRole.REPLY
    assert reply.frame.message == sj3.DataReply(1, b"02000100")
    assert reply.number == 2
    assert reply.answers == 1
    assert reply.latency_s == pytest.approx(0.0125)
    assert reply.anomalies == ()
    assert tape.sniffer.next_deadline is None
    stats = tape.sniffer.stats
    assert stats.paired == 1
    assert stats.frames == Counter({"request": 1, "reply": 1})
    assert stats.bytes == len(rq.read_status(1).frame) + len(status_reply(1))
    assert not stats.anomalies


def test_a_mixed_exchange_on_several_nodes_pairs_every_reply_and_flags_nothing() -> None:
    exchanges = [
        (rq.read_status(1).frame, status_reply(1)),
        (rq.read_monitor(2).frame, monitor_reply(2)),
        (rq.read_parameter(3, "A003").frame, value_reply(3, 5000)),
        (rq.write_parameter_raw(1, "A003", 6000).frame, ack(1)),
        (rq.run(2, 1).frame, ack(2)),
        (rq.set_frequency(3, 12.5).frame, nak(3, sj3.NakCode(16))),
        (rq.can_store(1).frame, sj3.encode_reply(sj3.AckDataReply(1, b"01"))),
    ]
    tape = Tape()
    t = 0.0
    for request, reply in exchanges:
        asked = tape.one(request, t)
        answered = tape.one(reply, t + 0.02)
        assert answered.answers == asked.number
        assert answered.frame.node == asked.frame.node
        t += 0.05
    broadcast = tape.one(rq.run(sj3.BROADCAST, 0).frame, t)
    assert broadcast.frame.role is FrameRole.REQUEST
    assert not broadcast.frame.expects_reply
    assert tape.sniffer.next_deadline is None  # no answer is due
    assert tape.tick(t + 10) == []
    assert tape.sniffer.stats.paired == len(exchanges)
    assert not tape.flagged()


def test_a_status_reply_shaped_like_a_set_frequency_request_is_the_pending_reads_answer() -> None:
    # "01" + "01020300": node 01, command 01, six digits - a valid request too.
    ambiguous = status_reply(1, b"01020300")
    tape = Tape()
    tape.one(rq.read_status(1).frame, 0.0)
    reply = tape.one(ambiguous, 0.01)
    assert (reply.frame.role, reply.answers) == (FrameRole.REPLY, 1)
    # With no status read pending, the same bytes are a request (and wait for an answer).
    alone = Tape().one(ambiguous, 1.0)
    assert alone.frame.role is FrameRole.REQUEST
    assert alone.frame.expects_reply
    # An expired status read still settles it: the answer, late.
    late = Tape()
    late.one(rq.read_status(1).frame, 0.0)
    assert len(late.tick(1.0)) == 1
    reply = late.one(ambiguous, 1.1)
    assert (reply.frame.role, reply.answers, reply.anomalies) == (
        FrameRole.REPLY,
        1,
        (Anomaly.LATE,),
    )


# -- the time-out ------------------------------------------------------------------------


@pytest.mark.parametrize(
    "request_",
    [
        rq.read_status(1),
        rq.read_monitor(2),
        rq.read_trip_history(3),
        rq.write_parameter_raw(4, "A003", 1),
    ],
    ids=["status", "monitor", "trip history", "write"],
)
def test_the_deadline_is_the_hosts_time_out_from_the_requests_first_byte(request_: Any) -> None:
    tape = Tape()
    tape.one(request_.frame, 5.0)
    deadline = deadline_of(request_, 5.0)
    assert tape.sniffer.next_deadline == pytest.approx(deadline)
    assert tape.tick(deadline) == []  # at the deadline: still in time
    [late] = tape.tick(deadline + 1e-6)
    assert isinstance(late, Unanswered)
    assert late.request.number == 1
    assert late.time == deadline + 1e-6
    assert late.anomalies == (Anomaly.UNANSWERED,)
    assert tape.tick(deadline + 10) == []  # reported once
    assert tape.sniffer.next_deadline is None


def test_a_fixed_time_out_replaces_the_computed_one() -> None:
    request = rq.read_status(1)
    tape = Tape(timing=BusTiming(fixed_timeout_s=0.3))
    tape.one(request.frame, 2.0)
    assert tape.sniffer.next_deadline == pytest.approx(
        2.0 - LINE.wire_time_s(len(request.frame)) + 0.3
    )


def test_a_reply_just_inside_the_time_out_is_in_time() -> None:
    request = rq.read_parameter(1, "A003")
    tape = Tape()
    tape.one(request.frame, 0.0)
    reply = tape.one(value_reply(1, 5), deadline_of(request, 0.0))
    assert reply.anomalies == ()
    assert reply.answers == 1
    assert not tape.flagged()


# -- unanswered and late -----------------------------------------------------------------


def test_an_unanswered_request_is_reported_by_the_next_chunk_before_what_it_completes() -> None:
    tape = Tape()
    tape.one(rq.read_status(1).frame, 0.0)
    unanswered, nxt = tape.feed(rq.read_status(2).frame, 1.0)
    assert isinstance(unanswered, Unanswered)
    assert unanswered.request.number == 1
    assert unanswered.time == 1.0
    assert isinstance(nxt, SniffedFrame)
    assert nxt.anomalies == ()
    assert tape.sniffer.stats.anomalies == Counter({"unanswered": 1})


def test_a_reply_after_the_time_out_is_late_and_still_paired() -> None:
    tape = Tape()
    request = rq.read_monitor(1)
    tape.one(request.frame, 0.0)
    deadline = deadline_of(request, 0.0)
    [unanswered] = tape.tick(deadline + 0.01)
    assert isinstance(unanswered, Unanswered)
    reply = tape.one(monitor_reply(1), deadline + 0.2)
    assert reply.anomalies == (Anomaly.LATE,)
    assert reply.answers == 1
    assert reply.latency_s == pytest.approx(deadline + 0.2)
    assert tape.flagged() == Counter({Anomaly.UNANSWERED: 1, Anomaly.LATE: 1})
    assert tape.sniffer.stats.paired == 1
    # Only once: the same reply again answers nothing.
    assert tape.one(monitor_reply(1), deadline + 0.3).anomalies == (Anomaly.UNSOLICITED,)


def test_a_late_reply_after_the_next_request_is_unsolicited() -> None:
    tape = Tape()
    tape.one(rq.read_status(1).frame, 0.0)
    tape.tick(1.0)
    tape.one(rq.read_status(2).frame, 1.0)
    stray = tape.one(status_reply(1), 1.01)
    assert stray.anomalies == (Anomaly.UNSOLICITED,)
    assert stray.answers is None
    assert tape.one(status_reply(2), 1.02).answers == 2
    assert tape.flagged() == Counter({Anomaly.UNANSWERED: 1, Anomaly.UNSOLICITED: 1})


def test_a_broadcast_waits_for_no_answer() -> None:
    tape = Tape()
    tape.one(rq.run(sj3.BROADCAST, 1).frame, 0.0)
    assert tape.sniffer.next_deadline is None
    assert tape.tick(100.0) == []
    assert tape.flush(100.0) == []
    assert not tape.flagged()


# -- unsolicited and two masters ---------------------------------------------------------


def test_a_duplicated_reply_is_unsolicited() -> None:
    tape = Tape()
    tape.one(rq.read_parameter(1, "A003").frame, 0.0)
    assert tape.one(value_reply(1, 5000), 0.01).answers == 1
    duplicate = tape.one(value_reply(1, 5000), 0.012)
    assert duplicate.anomalies == (Anomaly.UNSOLICITED,)
    assert (duplicate.answers, duplicate.latency_s) == (None, None)
    assert tape.sniffer.stats.paired == 1


def test_a_reply_from_another_node_answers_nobody_and_the_request_still_waits() -> None:
    tape = Tape()
    tape.one(rq.read_status(1).frame, 0.0)
    assert tape.one(status_reply(2), 0.005).anomalies == (Anomaly.UNSOLICITED,)
    # The wrong shape from the right node answers nobody either.
    assert tape.one(ack(1), 0.006).anomalies == (Anomaly.UNSOLICITED,)
    assert tape.one(status_reply(1), 0.01).answers == 1


def test_a_reply_with_nobody_asking_is_unsolicited() -> None:
    tape = Tape()
    assert tape.one(ack(7), 0.0).anomalies == (Anomaly.UNSOLICITED,)


def test_a_request_while_another_waits_is_two_masters() -> None:
    tape = Tape()
    tape.one(rq.read_status(1).frame, 0.0)
    second = tape.one(rq.read_monitor(2).frame, 0.005)
    assert second.anomalies == (Anomaly.TWO_MASTERS,)
    # Both requests wait: each answer is paired with its own, unflagged.
    monitor = tape.one(monitor_reply(2), 0.03)
    assert (monitor.answers, monitor.anomalies) == (2, ())
    status = tape.one(status_reply(1), 0.04)
    assert (status.answers, status.anomalies) == (1, ())
    assert tape.flagged() == Counter({Anomaly.TWO_MASTERS: 1})


def test_a_request_another_master_interrupted_is_still_reported_unanswered() -> None:
    tape = Tape()
    tape.one(rq.read_status(1).frame, 0.0)
    tape.one(rq.read_monitor(2).frame, 0.005)  # two masters
    tape.one(monitor_reply(2), 0.03)
    [late] = tape.tick(5.0)
    assert isinstance(late, Unanswered)
    assert late.request.number == 1
    assert tape.flagged() == Counter({Anomaly.TWO_MASTERS: 1, Anomaly.UNANSWERED: 1})


def test_a_broadcast_while_a_request_waits_is_two_masters() -> None:
    tape = Tape()
    tape.one(rq.read_status(1).frame, 0.0)
    assert tape.one(rq.run(sj3.BROADCAST, 0).frame, 0.005).anomalies == (Anomaly.TWO_MASTERS,)


def test_a_request_after_the_pending_one_timed_out_or_got_a_broken_answer_is_not_two_masters() -> (
    None
):
    timed_out = Tape()
    timed_out.one(rq.read_status(1).frame, 0.0)
    assert timed_out.feed(rq.read_status(1).frame, 1.0)[-1].anomalies == ()
    broken = Tape()
    broken.one(rq.read_status(1).frame, 0.0)
    broken.one(sj300_corrupt(status_reply(1)), 0.01)
    assert broken.one(rq.can_store(1).frame, 0.02).anomalies == ()
    assert broken.flagged() == Counter({Anomaly.BAD_CHECK: 1})


# -- bad check, broken, noise ------------------------------------------------------------


def test_a_corrupted_reply_is_a_bad_check_and_its_request_is_not_also_unanswered() -> None:
    tape = Tape()
    tape.one(rq.read_status(1).frame, 0.0)
    damaged = sj300_corrupt(status_reply(1))
    bad = tape.one(damaged, 0.01)
    assert bad.frame.role is FrameRole.BROKEN
    assert bad.frame.check_ok is False
    assert bad.frame.data == damaged
    assert bad.anomalies == (Anomaly.BAD_CHECK,)
    assert tape.tick(10.0) == []
    assert tape.flagged() == Counter({Anomaly.BAD_CHECK: 1})


def test_a_frame_with_a_good_check_code_but_no_valid_shape_is_broken_not_bad_check() -> None:
    tape = Tape()
    tape.one(rq.read_status(1).frame, 0.0)
    broken = tape.one(BAD_LENGTH, 0.01)
    assert broken.frame.role is FrameRole.BROKEN
    assert broken.frame.check_ok is None
    assert broken.frame.problem == "bad length"
    assert broken.anomalies == (Anomaly.BROKEN,)
    assert tape.tick(10.0) == []  # the broken frame was its answer
    # With nothing pending, a broken frame is flagged all the same.
    assert Tape().one(BAD_LENGTH, 0.0).anomalies == (Anomaly.BROKEN,)
    bad_bcc_ack = b"\x0201\x06" + bytes(reversed(sj3.bcc(b"01\x06"))) + b"\r"
    assert Tape().one(bad_bcc_ack, 0.0).anomalies == (Anomaly.BAD_CHECK,)


def test_bytes_outside_a_frame_are_noise_kept_byte_for_byte() -> None:
    tape = Tape()
    garbage = b"\x00\x7fjunk\xff"
    assert tape.feed(garbage, 0.0) == []  # a run of noise ends at the next frame
    noise, request = tape.feed(rq.read_status(1).frame, 0.01)
    assert isinstance(noise, SniffedFrame)
    assert isinstance(request, SniffedFrame)
    assert noise.frame.role is FrameRole.NOISE
    assert noise.frame.data == garbage
    assert noise.anomalies == (Anomaly.NOISE,)
    assert (noise.number, request.number) == (1, 2)
    assert request.anomalies == ()
    assert tape.one(status_reply(1), 0.02).answers == 2


def test_flush_reports_an_incomplete_frame_as_noise_and_the_pending_request() -> None:
    tape = Tape()
    request = rq.read_status(1)
    tape.one(request.frame, 0.0)
    [unanswered] = tape.flush(0.001)  # the line is gone before the time-out
    assert isinstance(unanswered, Unanswered)
    assert unanswered.request.number == 1
    tape = Tape()
    assert tape.feed(b"\x020104", 0.0) == []
    [cut] = tape.flush(0.5)
    assert isinstance(cut, SniffedFrame)
    assert cut.frame.role is FrameRole.NOISE
    assert cut.frame.data == b"\x020104"
    assert cut.anomalies == (Anomaly.NOISE,)


def test_every_anomaly_kind_on_one_line() -> None:
    tape = Tape()
    t = 0.0

    def at(data: bytes, dt: float = 0.01) -> None:
        nonlocal t
        t += dt
        tape.feed(data, t)

    at(rq.read_status(1).frame)
    at(sj300_corrupt(status_reply(1)))  # bad check code
    at(rq.read_status(2).frame, 1.0)
    at(BAD_LENGTH)  # broken frame
    at(b"\xffgarbage", 1.0)
    at(rq.read_status(3).frame)  # ends the noise
    at(rq.read_status(1).frame)  # two masters (3 still waits)
    at(status_reply(3))  # paired with the interrupted request
    at(status_reply(1))
    at(ack(7))  # nobody asked node 7: unsolicited
    at(rq.read_monitor(2).frame, 1.0)
    tape.tick(t + 1.0)  # unanswered
    at(monitor_reply(2), 1.1)  # late
    assert tape.flagged() == Counter(
        {
            Anomaly.BAD_CHECK: 1,
            Anomaly.BROKEN: 1,
            Anomaly.NOISE: 1,
            Anomaly.TWO_MASTERS: 1,
            Anomaly.UNSOLICITED: 1,
            Anomaly.UNANSWERED: 1,
            Anomaly.LATE: 1,
        }
    )
    assert set(tape.flagged()) == set(Anomaly)
    stats = tape.sniffer.stats
    assert stats.anomalies == Counter({a.value: 1 for a in Anomaly})
    assert stats.paired == 3  # node 3's (interrupted), node 1's, node 2's late answer


# -- FR-700 ------------------------------------------------------------------------------


def fr_status(station: int, data: bytes = b"02") -> bytes:
    return fr.encode_data_reply(station, data)


def test_fr700_pairs_reads_and_writes_and_tells_the_hosts_ack_from_the_drives() -> None:
    tape = Tape(FR)
    read = frq.read(1, 0x7A)
    asked = tape.one(read.frame, 0.0)
    assert asked.frame.role is FrameRole.REQUEST
    assert asked.frame.message == read
    data = tape.one(fr_status(1), 0.02)
    assert (data.frame.role, data.answers) == (FrameRole.REPLY, 1)
    assert data.latency_s == pytest.approx(0.02)
    host_ack = tape.one(fr.encode_host_ack(1), 0.03)  # after read data: the host's
    assert host_ack.frame.role is FrameRole.HOST_ANSWER
    assert host_ack.anomalies == ()
    write = frq.set_frequency(1, 30.0)
    tape.one(write.frame, 0.1)
    drive_ack = tape.one(fr.encode_ack(1), 0.12)  # after a write: the drive's
    assert (drive_ack.frame.role, drive_ack.answers) == (FrameRole.REPLY, 4)
    refused = frq.run(2, 1)
    tape.one(refused.frame, 0.2)
    nak = tape.one(fr.encode_nak(2, fr.Fr700NakCode(0xA)), 0.22)
    assert nak.answers == 6
    assert tape.sniffer.stats.paired == 3
    assert tape.sniffer.stats.frames == Counter({"request": 3, "reply": 3, "host answer": 1})
    assert not tape.flagged()


def test_fr700_a_corrupted_read_then_the_reoutput_request_then_the_resent_reply() -> None:
    tape = Tape(FR)
    tape.one(frq.read(1, 0x6F).frame, 0.0)
    damaged = fr700_corrupt(fr.encode_data_reply(1, b"0BB8"))
    bad = tape.one(damaged, 0.02)
    assert bad.frame.role is FrameRole.BROKEN
    assert bad.frame.check_ok is False
    assert bad.anomalies == (Anomaly.BAD_CHECK,)
    reoutput = tape.one(fr.encode_reoutput_request(1), 0.03)
    assert reoutput.frame.role is FrameRole.HOST_ANSWER
    assert reoutput.anomalies == ()
    resent = tape.one(fr.encode_data_reply(1, b"0BB8"), 0.05)
    assert resent.answers == 1
    assert resent.anomalies == ()
    assert tape.tick(10.0) == []
    assert tape.flagged() == Counter({Anomaly.BAD_CHECK: 1})


def test_fr700_unanswered_late_two_masters_unsolicited_and_noise() -> None:
    tape = Tape(FR)
    read = frq.read(1, 0x7A)
    tape.one(read.frame, 0.0)
    deadline = deadline_of(read, 0.0, dialect=FR)
    assert tape.sniffer.next_deadline == pytest.approx(deadline)
    [unanswered] = tape.tick(deadline + 0.001)
    assert isinstance(unanswered, Unanswered)
    assert tape.one(fr_status(1), deadline + 0.05).anomalies == (Anomaly.LATE,)
    tape.one(frq.read(1, 0x6F).frame, 1.0)
    assert tape.one(frq.read(2, 0x6F).frame, 1.001).anomalies == (Anomaly.TWO_MASTERS,)
    assert tape.one(fr.encode_data_reply(1, b"0000"), 1.02).answers == 3  # interrupted, paired
    assert tape.one(fr.encode_data_reply(2, b"0000"), 1.03).answers == 4
    assert tape.one(fr.encode_data_reply(2, b"0000"), 1.04).anomalies == (Anomaly.UNSOLICITED,)
    assert tape.feed(b"zz", 1.1) == []
    noise, _ = tape.feed(frq.read(2, 0x7A).frame, 1.2)
    assert isinstance(noise, SniffedFrame)
    assert noise.frame.data == b"zz"
    assert noise.anomalies == (Anomaly.NOISE,)
    assert tape.flagged() == Counter(
        {
            Anomaly.UNANSWERED: 1,
            Anomaly.LATE: 1,
            Anomaly.TWO_MASTERS: 1,
            Anomaly.UNSOLICITED: 1,
            Anomaly.NOISE: 1,
        }
    )


def test_fr700_a_reset_waits_for_no_answer() -> None:
    tape = Tape(FR)
    reset = tape.one(frq.reset(1).frame, 0.0)
    assert reset.frame.role is FrameRole.REQUEST
    assert not reset.frame.expects_reply
    assert tape.sniffer.next_deadline is None
    assert tape.tick(10.0) == []


# -- chunking never changes the result ---------------------------------------------------


@dataclass(frozen=True)
class Group:
    """Bytes the tap delivered at one time (a TCP segment, say)."""

    time: float
    data: bytes


def _feed_groups(
    dialect: Any, groups: Sequence[Group], cuts: Sequence[Sequence[int]] | None
) -> list[Report]:
    """Feed each group whole (*cuts* None) or in pieces cut at *cuts*, all at the group's time."""
    sniffer = LineSniffer(dialect, LINE, TIMING)
    reports: list[Report] = []
    end = 0.0
    for i, group in enumerate(groups):
        reports += sniffer.tick(group.time - 0.001)
        points = [0, *(cuts[i] if cuts is not None else ()), len(group.data)]
        for start, stop in itertools.pairwise(points):
            reports += sniffer.feed(group.data[start:stop], group.time)
        end = group.time
    reports += sniffer.tick(end + 0.05)
    reports += sniffer.flush(end + 10.0)
    return reports


def _check_chunking(dialect: Any, groups: list[Group], data: st.DataObject) -> None:
    cuts = [
        sorted(data.draw(st.sets(st.integers(1, max(1, len(g.data) - 1)), max_size=len(g.data))))
        if len(g.data) > 1
        else []
        for g in groups
    ]
    whole = _feed_groups(dialect, groups, None)
    chunked = _feed_groups(dialect, groups, cuts)
    bytewise = _feed_groups(dialect, groups, [range(1, len(g.data)) for g in groups])
    assert chunked == whole
    assert bytewise == whole
    # Every byte of the stream is in exactly one frame or noise piece, in order.
    pieces = [r.frame.data for r in whole if isinstance(r, SniffedFrame)]
    assert b"".join(pieces) == b"".join(g.data for g in groups)


def _groups(atoms: st.SearchStrategy[bytes]) -> st.SearchStrategy[list[Group]]:
    """Groups of 1..3 atoms, each after a gap that sometimes outlasts a time-out."""
    gap = st.sampled_from([0.0, 0.002, 0.01, 0.03, 0.2, 0.6])
    group = st.tuples(gap, st.lists(atoms, min_size=1, max_size=3))

    def timed(raw: list[tuple[float, list[bytes]]]) -> list[Group]:
        t, out = 1.0, []
        for dt, parts in raw:
            t += dt
            out.append(Group(t, b"".join(parts)))
        return out

    return st.lists(group, min_size=1, max_size=12).map(timed)


_NODES = st.integers(1, 3)
_SJ300_REQUESTS: list[Callable[[int], bytes]] = [
    lambda n: rq.read_status(n).frame,
    lambda n: rq.read_monitor(n).frame,
    lambda n: rq.read_parameter(n, "A003").frame,
    lambda n: rq.write_parameter_raw(n, "F002", 750).frame,
    lambda n: rq.run(n, 1).frame,
]
_SJ300_REPLIES: list[Callable[[int], bytes]] = [
    status_reply,
    lambda n: status_reply(n, b"01020300"),  # reads as a set-frequency request too
    monitor_reply,
    lambda n: value_reply(n, 5000),
    ack,
    nak,
    lambda n: sj300_corrupt(status_reply(n)),
    lambda n: sj300_corrupt(ack(n)),
]
SJ300_ATOMS = st.one_of(
    st.builds(lambda f, n: f(n), st.sampled_from(_SJ300_REQUESTS), _NODES),
    st.builds(lambda f, n: f(n), st.sampled_from(_SJ300_REPLIES), _NODES),
    st.just(rq.run(sj3.BROADCAST, 0).frame),
    st.just(BAD_LENGTH),
    st.binary(min_size=1, max_size=12),  # noise, with STX and CR sometimes among it
    st.builds(
        lambda f, n, k: f(n)[:k], st.sampled_from(_SJ300_REQUESTS), _NODES, st.integers(1, 6)
    ),
    st.just(b"\x02" + b"0" * 460),  # longer than any frame
    st.just(b"z" * 1000),  # a run of garbage longer than any frame
)


@PROPERTY
@given(groups=_groups(SJ300_ATOMS), data=st.data())
def test_sj300_any_chunking_gives_the_same_reports(
    groups: list[Group], data: st.DataObject
) -> None:
    _check_chunking(SJ, groups, data)


def _fr700_atoms(options: fr.Fr700LineOptions) -> st.SearchStrategy[bytes]:
    term = options.terminator
    requests: list[Callable[[int], bytes]] = [
        lambda n: frq.read(n, 0x7A, options=options).frame,
        lambda n: frq.read(n, 0x6F, options=options).frame,
        lambda n: frq.set_frequency(n, 30.0, options=options).frame,
        lambda n: frq.run(n, 1, options=options).frame,
        lambda n: frq.reset(n, options=options).frame,
    ]
    replies: list[Callable[[int], bytes]] = [
        lambda n: fr.encode_data_reply(n, b"02", term),
        lambda n: fr.encode_data_reply(n, b"0BB8", term),
        lambda n: fr.encode_ack(n, term),
        lambda n: fr.encode_nak(n, 2, term),
        lambda n: fr.encode_reoutput_request(n, term),
        lambda n: fr700_corrupt(fr.encode_data_reply(n, b"0BB8", term)),
    ]
    return st.one_of(
        st.builds(lambda f, n: f(n), st.sampled_from(requests), _NODES),
        st.builds(lambda f, n: f(n), st.sampled_from(replies), _NODES),
        st.binary(min_size=1, max_size=12),
        st.builds(lambda f, n, k: f(n)[:k], st.sampled_from(requests), _NODES, st.integers(1, 6)),
    )


_FR700_LINES = {
    "cr": fr.Fr700Dialect(),
    "crlf": fr.Fr700Dialect(terminator="\r\n"),
    "none": fr.Fr700Dialect(terminator=""),
    "none, no wait field": fr.Fr700Dialect(terminator="", wait_field=False),
}


@pytest.mark.parametrize("line", list(_FR700_LINES))
def test_fr700_any_chunking_gives_the_same_reports(line: str) -> None:
    dialect = _FR700_LINES[line]

    @PROPERTY
    @given(groups=_groups(_fr700_atoms(dialect.options)), data=st.data())
    def check(groups: list[Group], data: st.DataObject) -> None:
        _check_chunking(dialect, groups, data)

    check()
