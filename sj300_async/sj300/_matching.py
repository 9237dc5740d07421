"""Which reply answers which request.

The arbiter uses :func:`answers` to decide whether a frame that arrives
while a request is outstanding is its answer. Anything else (a reply from
another node, a reply of the wrong shape for the command) is not, and is
counted and discarded while the wait goes on.
"""

from __future__ import annotations

from ._commands import ReplyKind
from ._events import AckDataReply, AckReply, DataReply, NakReply, Reply
from ._requests import Request

__all__ = ["answers"]


def answers(request: Request, reply: Reply) -> bool:
    """True when *reply* has the node and the shape of an answer to *request*.

    A NAK from the addressed node answers any request. A broadcast has no answer.
    """
    if reply.node != request.node:
        return False
    if isinstance(reply, NakReply):
        return True
    spec = request.command.spec
    if spec.reply is ReplyKind.ACK:
        return isinstance(reply, AckReply)
    if spec.reply is ReplyKind.ACK_DATA:
        return isinstance(reply, AckDataReply) and len(reply.data) == spec.reply_length
    return isinstance(reply, DataReply) and len(reply.data) == spec.reply_length
