#!/usr/bin/env python3
"""Bring the gateway's web libraries into the package from the npm registry.

The plants the gateway runs in are air-gapped: the workbench page loads its
libraries from the package, never from a CDN, so they are vendored here, at
development time, by this script. The lock file
``sj300_async/gateway/http/static/vendor/vendor.json`` names, for each npm
package, the exact version, the registry's tarball and its ``dist.integrity``
(SRI, sha512), the files taken from the tarball and each one's sha256; the
files are written flattened into ``vendor/<name>/``.

Usage (from the repository's root, with any Python >= 3.11; stdlib only)::

    python scripts/vendor_web.py                    # fetch what the lock says, verify
    python scripts/vendor_web.py --check            # no network: files == lock's sha256
    python scripts/vendor_web.py --update uplot@1.6.32   # re-lock a version, then fetch

A tarball is checked against the lock's integrity before anything is read
from it, and only the listed files are taken (read from the archive, never
extracted onto the disk by tarfile). A failure is one line on stderr and
exit status 1.
"""

from __future__ import annotations

import argparse
import base64
import binascii
import hashlib
import http.client
import io
import json
import re
import sys
import tarfile
import urllib.error
import urllib.parse
import urllib.request
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path, PurePosixPath
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
LOCK = ROOT / "sj300_async" / "gateway" / "http" / "static" / "vendor" / "vendor.json"
REGISTRY = "https://registry.npmjs.org/"
# a hung registry must not hang the script: it fails with one line instead
TIMEOUT_S = 60
# far above any library the page would take; a bound on what is held in memory
MAX_TARBALL_BYTES = 64 * 1024 * 1024
_NAME = re.compile(r"[a-z0-9][a-z0-9._-]*")
# exact versions only: a range would make the lock's meaning depend on the day
_VERSION = re.compile(r"\d+\.\d+\.\d+(?:-[0-9A-Za-z.-]+)?")
_SHA256 = re.compile(r"[0-9a-f]{64}")
_LICENCE_NAMES = ("LICENSE", "LICENCE", "COPYING")
_LOCK_COMMENT = (
    "Written by scripts/vendor_web.py (docs/VENDORED.md): edit the files to take, "
    "then run the script; --update NAME@VERSION re-locks a version."
)


class VendorError(Exception):
    """A failure told as one line: the network, the registry, an integrity or a lock."""


@dataclass(frozen=True)
class LockedFile:
    """One file taken from a package's tarball."""

    path: str
    """Its path inside the tarball (``package/...``)."""
    sha256: str | None
    """The written file's sha256 (hex); ``None`` until the first fetch records it."""

    @property
    def target(self) -> str:
        """The file's name in ``vendor/<name>/``: the tarball's directories dropped."""
        return PurePosixPath(self.path).name


@dataclass(frozen=True)
class LockedPackage:
    """One npm package as the lock pins it."""

    name: str
    version: str
    license: str
    tarball: str
    integrity: str
    files: tuple[LockedFile, ...]


@dataclass(frozen=True)
class Problem:
    """A vendored file that is not what the lock says."""

    path: Path
    what: str

    def __str__(self) -> str:
        return f"{_shown(self.path)}: {self.what}"


def _shown(path: Path) -> str:
    try:
        return str(path.relative_to(ROOT))
    except ValueError:
        return str(path)


def _field(entry: dict[str, Any], key: str, where: str) -> str:
    value = entry.get(key)
    if not isinstance(value, str) or not value:
        raise VendorError(f"{where}: {key!r} must be a non-empty string")
    return value


def _parse_package(entry: object, where: str) -> LockedPackage:
    if not isinstance(entry, dict):
        raise VendorError(f"{where}: each package must be an object")
    name = _field(entry, "name", where)
    if not _NAME.fullmatch(name):
        raise VendorError(f"{where}: package name {name!r} is not a plain npm name")
    where = f"{where} ({name})"
    version = _field(entry, "version", where)
    if not _VERSION.fullmatch(version):
        raise VendorError(f"{where}: version {version!r} is not an exact version")
    tarball = _field(entry, "tarball", where)
    if not tarball.startswith(REGISTRY):
        raise VendorError(f"{where}: the tarball {tarball} is not on {REGISTRY}")
    integrity = _field(entry, "integrity", where)
    raw_files = entry.get("files")
    if not isinstance(raw_files, list) or not raw_files:
        raise VendorError(f"{where}: 'files' must be a non-empty list")
    files: list[LockedFile] = []
    for raw in raw_files:
        if not isinstance(raw, dict):
            raise VendorError(f"{where}: each file must be an object")
        path = _field(raw, "path", where)
        pure = PurePosixPath(path)
        if pure.is_absolute() or ".." in pure.parts or not pure.name:
            raise VendorError(f"{where}: file path {path!r} is not a path inside the tarball")
        sha256 = raw.get("sha256")
        if sha256 is not None and not (isinstance(sha256, str) and _SHA256.fullmatch(sha256)):
            raise VendorError(f"{where}: {path}: sha256 must be 64 lower-case hex digits or null")
        files.append(LockedFile(path, sha256))
    targets = [f.target for f in files]
    duplicates = sorted({t for t in targets if targets.count(t) > 1})
    if duplicates:
        raise VendorError(f"{where}: two files would be written as {', '.join(duplicates)}")
    # a library shipped without its licence is not shipped at all
    if not any(t.upper().startswith(_LICENCE_NAMES) for t in targets):
        raise VendorError(f"{where}: no licence file among the files to take")
    return LockedPackage(
        name=name,
        version=version,
        license=_field(entry, "license", where),
        tarball=tarball,
        integrity=integrity,
        files=tuple(files),
    )


def read_lock(lock: Path = LOCK) -> list[LockedPackage]:
    """The lock's packages, validated; :class:`VendorError` if it cannot be read."""
    try:
        data = json.loads(lock.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise VendorError(f"{_shown(lock)}: cannot read it: {exc}") from None
    packages = data.get("packages") if isinstance(data, dict) else None
    if not isinstance(packages, list):
        raise VendorError(f"{_shown(lock)}: 'packages' must be a list")
    parsed = [_parse_package(entry, _shown(lock)) for entry in packages]
    names = [p.name for p in parsed]
    if len(set(names)) != len(names):
        raise VendorError(f"{_shown(lock)}: a package is listed twice")
    return parsed


def write_lock(packages: Sequence[LockedPackage], lock: Path = LOCK) -> None:
    """Write the lock, sorted by name, as :func:`read_lock` reads it."""
    data = {
        "comment": _LOCK_COMMENT,
        "packages": [
            {
                "name": p.name,
                "version": p.version,
                "license": p.license,
                "tarball": p.tarball,
                "integrity": p.integrity,
                "files": [{"path": f.path, "sha256": f.sha256} for f in p.files],
            }
            for p in sorted(packages, key=lambda p: p.name)
        ],
    }
    lock.write_text(json.dumps(data, indent=2) + "\n", encoding="utf-8")


def check(packages: Sequence[LockedPackage], vendor_dir: Path) -> list[Problem]:
    """The vendored files under *vendor_dir* that differ from the lock (none: all good).

    Each listed file must exist with the locked sha256, and a package's
    directory must hold nothing else. No network.
    """
    problems: list[Problem] = []
    for package in packages:
        directory = vendor_dir / package.name
        for locked in package.files:
            path = directory / locked.target
            if not path.is_file():
                problems.append(Problem(path, "missing (run scripts/vendor_web.py)"))
                continue
            digest = hashlib.sha256(path.read_bytes()).hexdigest()
            if locked.sha256 is None:
                problems.append(Problem(path, "the lock has no sha256 for it"))
            elif digest != locked.sha256:
                problems.append(
                    Problem(path, f"sha256 {digest} does not match the lock's {locked.sha256}")
                )
        if directory.is_dir():
            expected = {f.target for f in package.files}
            for path in sorted(directory.iterdir()):
                if path.name not in expected:
                    problems.append(Problem(path, "not in the lock"))
    return problems


def _get(url: str) -> bytes:
    request = urllib.request.Request(url, headers={"User-Agent": "sj300_async vendor_web.py"})
    try:
        with urllib.request.urlopen(request, timeout=TIMEOUT_S) as response:
            body: bytes = response.read(MAX_TARBALL_BYTES + 1)
    except urllib.error.HTTPError as exc:
        raise VendorError(f"{url}: the registry answered {exc.code} {exc.reason}") from None
    except urllib.error.URLError as exc:
        raise VendorError(f"{url}: cannot reach the registry: {exc.reason}") from None
    except (OSError, http.client.HTTPException) as exc:
        raise VendorError(f"{url}: the download failed: {exc or type(exc).__name__}") from None
    if len(body) > MAX_TARBALL_BYTES:
        raise VendorError(f"{url}: larger than {MAX_TARBALL_BYTES} bytes")
    return body


def verify_integrity(data: bytes, integrity: str, what: str) -> None:
    """Raise :class:`VendorError` unless *data* matches the SRI string (sha512)."""
    algorithm, _, encoded = integrity.partition("-")
    if algorithm != "sha512":
        raise VendorError(f"{what}: integrity {integrity!r} is not sha512 (SRI form)")
    try:
        expected = base64.b64decode(encoded, validate=True)
    except binascii.Error:
        raise VendorError(f"{what}: integrity {integrity!r} is not valid base64") from None
    actual = hashlib.sha512(data).digest()
    if actual != expected:
        got = "sha512-" + base64.b64encode(actual).decode("ascii")
        raise VendorError(
            f"{what}: integrity mismatch: the tarball is {got}, the lock says {integrity}"
        )


def _take(data: bytes, package: LockedPackage) -> dict[LockedFile, bytes]:
    """The listed files' contents, read from the (verified) tarball."""
    what = f"{package.name} {package.version}"
    taken: dict[LockedFile, bytes] = {}
    try:
        with tarfile.open(fileobj=io.BytesIO(data), mode="r:gz") as archive:
            for locked in package.files:
                try:
                    member = archive.getmember(locked.path)
                except KeyError:
                    raise VendorError(f"{what}: no file {locked.path} in the tarball") from None
                stream = archive.extractfile(member) if member.isfile() else None
                if stream is None:
                    raise VendorError(f"{what}: {locked.path} in the tarball is not a file")
                taken[locked] = stream.read()
    except (tarfile.TarError, EOFError, OSError) as exc:
        raise VendorError(f"{what}: cannot read the tarball: {exc}") from None
    return taken


def fetch(package: LockedPackage, vendor_dir: Path) -> LockedPackage:
    """Download, verify and write *package*'s files; the package with their sha256.

    A file whose lock has a sha256 must match it (the registry's tarball is
    immutable, so a difference is a lock edited by hand); one without gets it
    recorded. Nothing is written unless every file is right.
    """
    what = f"{package.name} {package.version}"
    data = _get(package.tarball)
    verify_integrity(data, package.integrity, what)
    taken = _take(data, package)
    recorded: list[LockedFile] = []
    for locked, content in taken.items():
        digest = hashlib.sha256(content).hexdigest()
        if locked.sha256 is not None and digest != locked.sha256:
            raise VendorError(
                f"{what}: {locked.path} has sha256 {digest}, the lock says {locked.sha256}"
            )
        recorded.append(replace(locked, sha256=digest))
    directory = vendor_dir / package.name
    directory.mkdir(parents=True, exist_ok=True)
    # the directory is the script's alone: a file the lock no longer takes goes
    for stale in directory.iterdir():
        if stale.name not in {f.target for f in package.files}:
            stale.unlink()
    for locked, content in taken.items():
        (directory / locked.target).write_bytes(content)
    return replace(package, files=tuple(recorded))


def resolve(package: LockedPackage, version: str) -> LockedPackage:
    """*package* at *version*: the registry's tarball, integrity and licence, no sha256 yet."""
    what = f"{package.name}@{version}"
    url = REGISTRY + urllib.parse.quote(package.name, safe="") + "/" + version
    try:
        meta = json.loads(_get(url))
    except VendorError as exc:
        if " answered 404 " in str(exc):
            raise VendorError(f"{what}: the registry has no such version") from None
        raise
    except (UnicodeDecodeError, json.JSONDecodeError):
        raise VendorError(f"{what}: the registry's answer is not JSON") from None
    dist = meta.get("dist") if isinstance(meta, dict) else None
    if not isinstance(dist, dict):
        raise VendorError(f"{what}: the registry's answer has no 'dist'")
    tarball, integrity = dist.get("tarball"), dist.get("integrity")
    if not isinstance(tarball, str) or not tarball.startswith(REGISTRY):
        raise VendorError(f"{what}: the registry's tarball {tarball!r} is not on {REGISTRY}")
    if not isinstance(integrity, str) or not integrity.startswith("sha512-"):
        raise VendorError(f"{what}: the registry gives no sha512 integrity ({integrity!r})")
    licence = meta.get("license")
    return replace(
        package,
        version=version,
        license=licence if isinstance(licence, str) and licence else package.license,
        tarball=tarball,
        integrity=integrity,
        files=tuple(replace(f, sha256=None) for f in package.files),
    )


def _parse_spec(spec: str) -> tuple[str, str]:
    name, at, version = spec.rpartition("@")
    if not at or not _NAME.fullmatch(name) or not _VERSION.fullmatch(version):
        raise VendorError(f"--update {spec}: expected NAME@VERSION with an exact version")
    return name, version


def _check(lock: Path) -> int:
    problems = check(read_lock(lock), lock.parent)
    for problem in problems:
        print(f"vendor_web: {problem}", file=sys.stderr)
    return 1 if problems else 0


def _fetch(lock: Path, update: str | None) -> int:
    packages = read_lock(lock)
    only: str | None = None
    if update is not None:
        only, version = _parse_spec(update)
        if only not in {p.name for p in packages}:
            raise VendorError(
                f"{only} is not in {_shown(lock)}: add its entry with the files to take first"
            )
        packages = [resolve(p, version) if p.name == only else p for p in packages]
    fetched: list[LockedPackage] = []
    for package in packages:
        if only is not None and package.name != only:
            fetched.append(package)
            continue
        done = fetch(package, lock.parent)
        recorded = any(f.sha256 is None for f in package.files)
        names = ", ".join(f.target for f in done.files)
        note = "sha256 recorded in the lock" if recorded else "sha256 as locked"
        print(f"{done.name} {done.version} ({done.license}): {names} ({note})")
        fetched.append(done)
    if fetched != packages or only is not None:
        write_lock(fetched, lock)
    return _check(lock)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="scripts/vendor_web.py",
        description="Vendor the gateway's web libraries from the npm registry, as the lock says.",
    )
    mode = parser.add_mutually_exclusive_group()
    mode.add_argument(
        "--check",
        action="store_true",
        help="no network: verify the vendored files against the lock's sha256",
    )
    mode.add_argument(
        "--update",
        metavar="NAME@VERSION",
        help="re-lock NAME at VERSION from the registry, then fetch it",
    )
    parser.add_argument(
        "--lock",
        type=Path,
        default=LOCK,
        help="the lock file; the files go beside it, in <name>/ (default: %(default)s)",
    )
    args = parser.parse_args(argv)
    try:
        if args.check:
            return _check(args.lock)
        return _fetch(args.lock, args.update)
    except VendorError as exc:
        print(f"vendor_web: {exc}", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
