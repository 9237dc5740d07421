"""Speed tricks for decoders on a trusted path, kept in one place with their equivalence tests.

Each builds exactly the object the dataclass's own constructor would build
(tests/core/test_fast_paths.py proves it field by field), at less cost. Use
them only where a benchmark row needs them (the codec benchmark's decoders).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import fields
from typing import Any

__all__ = ["slot_setters", "unfrozen_twin"]


def slot_setters(cls: type) -> tuple[Callable[[Any, Any], None], ...]:
    """The ``__set__`` of each field's slot of a frozen, slotted dataclass, in field order.

    For decoders on a trusted path (values already checked): ``obj =
    object.__new__(cls)`` and one setter call per field build the same object
    as ``cls(...)``, which has no ``__post_init__`` here, without the generated
    ``__init__``'s ``object.__setattr__`` call per field.
    """
    return tuple(vars(cls)[f.name].__set__ for f in fields(cls))


def unfrozen_twin(cls: type) -> type:
    """A plain class with the same slots as the frozen, slotted dataclass *cls*.

    For decoders on a trusted path that fill many fields: set the twin's
    attributes (plain slot stores, the cheapest there are), then assign
    ``__class__ = cls``. Python allows that because the two layouts are the
    same, and the result is the object ``cls(...)`` would have built (no
    ``__post_init__`` here), for less than the setters of :func:`slot_setters`
    once there are many fields.
    """
    return type(f"Unfrozen{cls.__name__}", (), {"__slots__": vars(cls)["__slots__"]})
