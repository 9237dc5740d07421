"""A third protocol, defined entirely inside the tests: "toy", a line-per-frame ASCII protocol.

It proves that adding a protocol is one package plus one registry entry, with
no library file touched: :func:`sj300_async.bus.register_protocol` is the
entry, this package the protocol. The bus, arbiter, URL parser, poller and
``sim://`` serve it as they serve SJ300 and FR-700.

Wire format (``NN`` a two-digit node 1..9, lines end with LF):

- request ``?NN R KEY`` reads a register, ``?NN W KEY VALUE`` writes one;
- reply ``!NN VALUE`` (read), ``!NN OK`` (write), ``#NN CODE`` (refusal).

URL option: ``upper=1`` makes the host send its keys in upper case.
"""

from ._protocol import (
    TOY_DIALECT,
    ToyDialect,
    ToyDrive,
    ToyNak,
    ToyOk,
    ToyParser,
    ToyReply,
    ToyRequest,
    ToySimulatedBus,
    ToyValue,
    simulate,
)

__all__ = [
    "TOY_DIALECT",
    "ToyDialect",
    "ToyDrive",
    "ToyNak",
    "ToyOk",
    "ToyParser",
    "ToyReply",
    "ToyRequest",
    "ToySimulatedBus",
    "ToyValue",
    "simulate",
]
