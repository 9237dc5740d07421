"""The workbench's vendored web libraries are the ones the lock pins (no network).

The files are written by ``scripts/vendor_web.py``; these tests use its own
check, so the lock's meaning is written once.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from scripts import vendor_web

VENDOR = vendor_web.LOCK.parent


def test_the_lock_lies_in_the_package() -> None:
    root = Path(__file__).parents[2]
    assert root / "sj300_async" / "gateway" / "http" / "static" / "vendor" == VENDOR
    assert [p.name for p in vendor_web.read_lock()] == ["uplot"]


def test_the_shipped_files_match_the_lock() -> None:
    problems = vendor_web.check(vendor_web.read_lock(), VENDOR)
    assert not problems, "\n".join(map(str, problems))


def test_each_package_ships_its_licence() -> None:
    for package in vendor_web.read_lock():
        licence = VENDOR / package.name / "LICENSE"
        assert licence.is_file(), f"{package.name} is vendored without its LICENSE"
        assert package.license in licence.read_text(encoding="utf-8")


def test_a_corrupted_copy_is_reported_naming_the_file(tmp_path: Path) -> None:
    packages = vendor_web.read_lock()
    shutil.copytree(VENDOR, tmp_path, dirs_exist_ok=True)
    assert vendor_web.check(packages, tmp_path) == []
    corrupted = tmp_path / "uplot" / "uPlot.iife.min.js"
    corrupted.write_bytes(corrupted.read_bytes().replace(b"uPlot", b"uPlat", 1))

    problems = vendor_web.check(packages, tmp_path)

    assert [p.path for p in problems] == [corrupted]
    assert "does not match the lock's" in problems[0].what
    assert str(corrupted) in str(problems[0])


def test_a_missing_file_and_a_stray_one_are_reported(tmp_path: Path) -> None:
    packages = vendor_web.read_lock()
    shutil.copytree(VENDOR, tmp_path, dirs_exist_ok=True)
    (tmp_path / "uplot" / "LICENSE").unlink()
    (tmp_path / "uplot" / "uPlot.js").write_text("// not locked\n", encoding="utf-8")

    problems = {p.path.name: p.what for p in vendor_web.check(packages, tmp_path)}

    assert problems == {
        "LICENSE": "missing (run scripts/vendor_web.py)",
        "uPlot.js": "not in the lock",
    }


def test_check_mode_exits_1_naming_the_file(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    shutil.copytree(VENDOR, tmp_path, dirs_exist_ok=True)
    assert vendor_web.main(["--check", "--lock", str(tmp_path / "vendor.json")]) == 0
    (tmp_path / "uplot" / "uPlot.min.css").write_text("/* edited */\n", encoding="utf-8")

    assert vendor_web.main(["--check", "--lock", str(tmp_path / "vendor.json")]) == 1

    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1
    assert err[0].startswith(f"vendor_web: {tmp_path / 'uplot' / 'uPlot.min.css'}: sha256 ")


def test_an_integrity_mismatch_is_one_error() -> None:
    data = b"not the tarball"
    with pytest.raises(vendor_web.VendorError, match=r"^uplot 1\.6: integrity mismatch: "):
        vendor_web.verify_integrity(data, vendor_web.read_lock()[0].integrity, "uplot 1.6")
