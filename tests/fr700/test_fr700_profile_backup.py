"""What the FR-700 profile tells `sj300 params`: which numbers to walk, which to leave alone."""

from __future__ import annotations

from sj300_async.fr700 import FR700_PARAMETERS, Fr700NakCode
from sj300_async.profiles import get_profile

PROFILE = get_profile("fr700")


def test_a_backup_walks_every_number_the_link_extension_reaches() -> None:
    addressable = PROFILE.parameters.addressable()
    assert addressable == tuple(f"Pr.{n}" for n in range(1000))  # banks 0..9, 100 offsets
    catalogued = PROFILE.parameters.codes()
    assert len(catalogued) == len(FR700_PARAMETERS) < len(addressable)
    assert set(catalogued) <= set(addressable)
    assert PROFILE.capabilities.parameter_backup


def test_only_nak_b_means_absent() -> None:
    assert PROFILE.absent(Fr700NakCode.INSTRUCTION_CODE)
    others = set(Fr700NakCode) - {Fr700NakCode.INSTRUCTION_CODE}
    assert not any(PROFILE.absent(code) for code in others)


def test_what_a_restore_leaves_alone() -> None:
    addressable = set(PROFILE.parameters.addressable())
    line, kept, last = (
        set(PROFILE.line_parameters),
        set(PROFILE.kept_parameters),
        set(PROFILE.last_parameters),
    )
    assert PROFILE.address_parameter == "Pr.117"
    assert {f"Pr.{n}" for n in range(118, 125)} <= line  # the PU connector's settings
    assert {"Pr.337", "Pr.341", "Pr.549"} <= line  # the RS-485 terminals', the protocol
    assert {"Pr.331", "Pr.343", "Pr.900", "Pr.902", "Pr.999"} <= kept
    assert PROFILE.last_parameters[-2:] == ("Pr.79", "Pr.77")  # the mode, then the lock
    assert {"Pr.338", "Pr.339", "Pr.340", "Pr.342", "Pr.550", "Pr.551"} <= last
    groups = [{PROFILE.address_parameter}, line, kept, last]
    assert sum(map(len, groups)) == len(set().union(*groups))  # no code in two groups
    assert set().union(*groups) <= addressable
