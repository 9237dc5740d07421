"""Which reply answers which request.

The arbiter uses :func:`answers` to decide whether a frame that arrives
while a request is outstanding is its answer. Anything else (a reply from
another node, a reply of the wrong shape for the command) is not, and is
counted and discarded while the wait goes on.
"""

from __future__ import annotations

from ._commands import COMMAND_SPECS, Command, ReplyKind
from ._events import AckDataReply, AckReply, DataReply, NakReply, Reply
from ._requests import Request

__all__ = ["answers"]

_KINDS: dict[ReplyKind, type[Reply]] = {
    ReplyKind.ACK: AckReply,
    ReplyKind.ACK_DATA: AckDataReply,
    ReplyKind.DATA: DataReply,
}
#: Each command's positive answer: its reply class (exact: the parser makes no
#: subclasses) and its data length (0 for a bare ACK). Looked up once per
#: frame, where the command's spec would take a property call and two tests.
_SHAPES: dict[Command, tuple[type[Reply], int]] = {
    command: (_KINDS[spec.reply], spec.reply_length) for command, spec in COMMAND_SPECS.items()
}


def answers(request: Request, reply: Reply) -> bool:
    """True when *reply* has the node and the shape of an answer to *request*.

    A NAK from the addressed node answers any request. A broadcast has no answer.
    """
    if reply.node != request.node:
        return False
    kind = type(reply)
    if kind is NakReply:
        return True
    shape, length = _SHAPES[request.command]
    if kind is not shape:
        return False
    return kind is AckReply or len(reply.data) == length  # type: ignore[union-attr]
