"""The oracle: what each drive's parameters may hold, so a wrong value cannot pass unseen.

Every (node, parameter) the soak writes has exactly one owner task, so the
writes and reads of one key are sequential and the oracle needs no locks.

Values are distinct per node: node 3 only ever holds 3xxx in A020,
30001..39999 in A092, so a reply from the wrong node, or a late reply to an
older request, reads as a value the oracle does not allow.

A write that fails with a typed error may or may not have happened (the
request may have reached the drive and only the reply was lost). After it
the oracle allows the old value(s) *and* the new one, until the next
successful write or read settles the key again.
"""

from __future__ import annotations

from dataclasses import dataclass, field

#: The parameters the soaks write, with the raw values each node may be given.
#: A020 multi-speed 0 (0..40000), A092 / A093 ramp times 2 (1..360000),
#: B012 thermal level (0..99999), F001 the setpoint (set with command 01; it
#: must stay <= A004 = 50.00 Hz on a European drive).
KEYS = ("A020", "A092", "A093", "B012", "F001")


def value_for(code: str, node: int, serial: int) -> int:
    """The *serial*-th value of *code* on *node*: distinct from every other node's."""
    if code == "A020":
        return node * 1000 + serial % 1000
    if code in ("A092", "A093", "B012"):
        return node * 10000 + 1 + serial % 9999
    if code == "F001":
        return node * 100 + serial % 100  # 1.00 .. 8.99 Hz
    raise KeyError(code)


@dataclass
class Oracle:
    """Allowed raw values per (node, code). See the module docstring."""

    allowed: dict[tuple[int, str], set[int]] = field(default_factory=dict)
    #: Successful reads checked against the oracle.
    checked: int = 0
    #: Reads that returned a value the oracle did not allow.
    wrong: list[str] = field(default_factory=list)

    def settle(self, node: int, code: str, raw: int) -> None:
        self.allowed[(node, code)] = {raw}

    def wrote(self, node: int, code: str, raw: int) -> None:
        """A write was acknowledged."""
        self.settle(node, code, raw)

    def write_failed(self, node: int, code: str, raw: int) -> None:
        """A write ended in a typed error (or was cancelled): it may have happened."""
        self.allowed[(node, code)].add(raw)

    def read(self, node: int, code: str, raw: int) -> bool:
        """Check a value read from the drive; record it when it is wrong."""
        self.checked += 1
        allowed = self.allowed[(node, code)]
        if raw not in allowed:
            self.wrong.append(f"node {node:02d} {code} read {raw}, allowed {sorted(allowed)}")
            return False
        self.settle(node, code, raw)
        return True

    def check_constant(self, what: str, got: object, expected: object) -> bool:
        """A value that never changes (C072 is the node's own address)."""
        self.checked += 1
        if got != expected:
            self.wrong.append(f"{what}: got {got!r}, expected {expected!r}")
            return False
        return True
