"""A protocol's profile, found through its dialect and imported on first use.

The dialect names its profile (``Dialect.profile``: ``"module:attribute"``)
as it names its simulator, so registering a protocol
(:func:`sj300_async.bus.register_protocol`) registers its profile too, and
nothing here names a protocol.
"""

from __future__ import annotations

from ..bus import get_dialect, load_object, protocol_names
from ..wire import LocalProtocolError
from ._profile import Profile

__all__ = ["get_profile", "profiled_protocols"]

#: Loaded profiles by where they live (a protocol registered again may name another).
_loaded: dict[str, Profile] = {}


def get_profile(protocol: str) -> Profile:
    """The profile of registered protocol *protocol*.

    Raises:
        LocalProtocolError: no such protocol, or one whose dialect names no profile
            (the library can talk to its drives, but the gateway and the
            command line do not know what their answers mean).
    """
    where = get_dialect(protocol).profile
    if where is None:
        raise LocalProtocolError(
            f"protocol {protocol!r} has no profile (its dialect names none): "
            "the gateway and the command line cannot serve it"
        )
    profile = _loaded.get(where)
    if profile is None:
        profile = _loaded[where] = load_object(where)
    if profile.name != protocol:
        raise LocalProtocolError(f"protocol {protocol!r} names the profile of {profile.name!r}")
    return profile


def profiled_protocols() -> tuple[str, ...]:
    """The registered protocols that have a profile, in registration order."""
    return tuple(name for name in protocol_names() if get_dialect(name).profile is not None)
