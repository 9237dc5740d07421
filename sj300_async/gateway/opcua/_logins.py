"""Password logins judged before asyncua asks: encrypted as the endpoint asks, within budgets,
checked off the event loop.

asyncua asks the user manager (:class:`._security.Users`) for a user
synchronously, inside ActivateSession; a scrypt check there holds the
event loop about 65 ms, the loop that polls the lines and runs the lapse
stops. :mod:`._hooks` therefore hands each ActivateSession carrying a
UserNameIdentityToken to :meth:`Logins.judge` first, which it awaits:

1. **Encrypted where the endpoint asks** (OPC UA Part 4, 7.36.4
   UserNameIdentityToken): the token's UserTokenPolicy names a security
   policy, or the endpoint's applies; unless that is None the password
   must come encrypted with the policy's asymmetric algorithm. asyncua
   takes it in clear whatever the policy (issue 41: the None and Sign
   endpoints, whose policy is Basic256Sha256). A token in clear there is
   refused ``BadIdentityTokenInvalid`` (it does not conform to its
   policy), one encrypted with another algorithm (asyncua would decrypt
   RSA 1.5 too) ``BadSecurityPolicyRejected``; a token on a channel no
   endpoint offers (discovery only) conforms to nothing:
   ``BadIdentityTokenInvalid``. Counted ``unencrypted``.
2. **Budgets per client address and per user name** (:class:`KeyedBudget`),
   spent before the token is decrypted (an RSA decryption) and checked: a
   burst past them is refused unchecked (``rate``). The name's budget is
   twice the address's in burst and in rate, so one address, spending at
   most its own, can never spend a name's: a stream of wrong passwords from
   one address never refuses a correct login from another (issue 41: the
   global budget refused the operator 6 of 6 times). Only configured names
   have a budget of their own: a name nobody has cannot be guessed into,
   and names sent at random must not fill the table. A login that succeeds
   gives back what it spent.
3. **The check off the loop** (:class:`PasswordChecks`: one thread,
   bounded queue; past it ``busy``, refused unchecked and given back).
   Unknown names are checked against a fixed hash, so a refusal takes the
   same time either way.

A refusal is answered by :mod:`._hooks` (``BadUserAccessDenied`` for a
password, the rate and busy), asyncua never asked. An accepted login is
handed to :class:`._security.Users` (:func:`._security.hand_over`), which
asyncua then asks synchronously, for the same name and password, in the
same task.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Hashable, Sequence
from dataclasses import dataclass
from typing import Final

from asyncua import ua
from asyncua.crypto.security_policies import SECURITY_POLICY_TYPE_MAP, SecurityPolicyNone

from .. import KeyedBudget, PasswordChecks, excerpt
from ._security import DUMMY_HASH, Users, hand_over

__all__ = ["Channel", "LoginLimits", "Logins", "required_encryption"]

_log = logging.getLogger("sj300_async.gateway.opcua")

_NONE: Final = SecurityPolicyNone.URI
#: Each security policy's asymmetric encryption algorithm (what a password is encrypted with).
_ALGORITHMS: Final = {
    policy.URI: policy.AsymmetricEncryptionURI for policy, _, _ in SECURITY_POLICY_TYPE_MAP.values()
}
_REFUSED: Final = ua.StatusCodes.BadUserAccessDenied


@dataclass(frozen=True, slots=True)
class LoginLimits:
    """The password budget of one client address: *burst* at once, one more each *interval_s*."""

    burst: int
    interval_s: float


@dataclass(frozen=True, slots=True)
class Channel:
    """What a login came by: its secure channel's policy and mode, the server's endpoints."""

    policy_uri: str
    mode: ua.MessageSecurityMode
    endpoints: Sequence[ua.EndpointDescription]


def required_encryption(channel: Channel, policy_id: str | None) -> str | None:
    """The algorithm a UserNameIdentityToken's password must be encrypted with on *channel*:
    ``""`` for none (clear is what the policy says), None when no endpoint offers a
    UserName token there (the token conforms to nothing).

    The token's UserTokenPolicy is the one its *policy_id* names, or the endpoint's
    only one; its security policy, or the endpoint's when it names none (Part 4, 7.36.4).
    """
    for endpoint in channel.endpoints:
        offered = (endpoint.SecurityPolicyUri, endpoint.SecurityMode)
        if offered != (channel.policy_uri, channel.mode):
            continue
        policies = [
            token
            for token in endpoint.UserIdentityTokens or ()
            if token.TokenType == ua.UserTokenType.UserName
        ]
        named = [token for token in policies if token.PolicyId == policy_id] or policies
        if not named:
            continue
        uri = named[0].SecurityPolicyUri or endpoint.SecurityPolicyUri
        return "" if uri == _NONE else _ALGORITHMS.get(uri, uri)
    return None


class Logins:
    """Logins judged before asyncua asks for them (see the module docstring).

    Args:
        users: the configured users (their hashes; the refusals are counted there).
        limits: one client address's budget (a name's is twice it).
        checks: where passwords are checked.
    """

    def __init__(self, users: Users, limits: LoginLimits, checks: PasswordChecks) -> None:
        self.users = users
        per_s = 1.0 / limits.interval_s
        self.by_address = KeyedBudget(limits.burst, per_s)
        self.by_name = KeyedBudget(2 * limits.burst, 2 * per_s)
        self.checks = checks

    async def judge(
        self,
        address: Hashable,
        token: ua.UserNameIdentityToken,
        channel: Channel,
        decrypt: Callable[[], tuple[str, str]],
    ) -> int | None:
        """None when *token* logs in (handed over to :class:`Users`), or the status code
        refusing it (counted). *decrypt*: the token's name and password (asyncua's)."""
        name = token.UserName or ""
        required = required_encryption(channel, token.PolicyId)
        algorithm = token.EncryptionAlgorithm or ""
        if required is None or (required and not algorithm):
            return self._refuse("unencrypted", name, ua.StatusCodes.BadIdentityTokenInvalid)
        if required and algorithm != required:
            return self._refuse("unencrypted", name, ua.StatusCodes.BadSecurityPolicyRejected)
        known = self.users.stored(name) is not None
        if not self.by_address.spend(address):
            return self._refuse("rate", name, _REFUSED)
        if known and not self.by_name.spend(name):
            self.by_address.refund(address)
            return self._refuse("rate", name, _REFUSED)
        try:
            name, password = decrypt()
        except Exception:  # a token the key does not open, or not a password once opened
            return self._refuse("token", name, ua.StatusCodes.BadIdentityTokenInvalid)
        stored = self.users.stored(name)
        verified = await self.checks.verify(password, stored or DUMMY_HASH)
        if verified is None or (verified and stored is not None):
            self.by_address.refund(address)
            if known:
                self.by_name.refund(name)
        if verified is None:
            return self._refuse("busy", name, _REFUSED)
        if not verified or stored is None:
            return self._refuse("password", name, _REFUSED)
        hand_over(name, password)
        return None

    def _refuse(self, reason: str, name: str, status: int) -> int:
        self.users.refusals[reason] += 1
        _log.debug("opcua: a login as %r refused (%s)", excerpt(name, 64), reason)
        return status
