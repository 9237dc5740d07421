"""The server's application certificate: the configured pair, or one generated at first start.

OPC UA's secure channel (Basic256Sha256) signs and encrypts with the
application instance certificate, whose subject alternative names carry
the application URI a client checks against the server's description.
When neither configured file exists the first start generates a
self-signed pair (asyncua's generator, which follows OPC 10000-6 6.2.2)
with the directory made 0700 and the key 0600, and the next start loads
the same pair: clients that trusted it keep trusting it. A certificate the
user brings is used as is, and its URI becomes the server's application
URI.
"""

from __future__ import annotations

import errno
import logging
import os
import socket
from dataclasses import dataclass
from pathlib import Path
from typing import Final

from asyncua.crypto import uacrypto
from cryptography import x509
from cryptography.hazmat.primitives import hashes, serialization
from cryptography.x509.oid import ExtendedKeyUsageOID

__all__ = [
    "ServerCertificate",
    "check_pair",
    "free_port",
    "load_or_generate",
    "load_trusted",
]

_log = logging.getLogger("sj300_async.gateway.opcua")

#: How long a generated certificate is valid.
GENERATED_DAYS: Final = 3650


@dataclass(frozen=True, slots=True)
class ServerCertificate:
    """The pair the server uses, and what became of it at start."""

    certificate: Path
    private_key: Path
    #: The application URI in the certificate (the server's own).
    application_uri: str
    #: True when this start generated the pair.
    generated: bool
    #: SHA-1 thumbprint, hex (what clients show to be trusted).
    thumbprint: str


def _uri_of(certificate: x509.Certificate) -> str | None:
    try:
        names = certificate.extensions.get_extension_for_class(x509.SubjectAlternativeName)
    except x509.ExtensionNotFound:
        return None
    uris = names.value.get_values_for_type(x509.UniformResourceIdentifier)
    return uris[0] if uris else None


def _load(path: Path) -> x509.Certificate:
    data = path.read_bytes()
    if data.lstrip().startswith(b"-----BEGIN"):
        return x509.load_pem_x509_certificate(data)
    return x509.load_der_x509_certificate(data)


def _generate(certificate: Path, private_key: Path, application_uri: str) -> None:
    from asyncua.crypto import cert_gen

    host = socket.gethostname()
    key = cert_gen.generate_private_key()
    cert = cert_gen.generate_self_signed_app_certificate(
        key,
        f"sj300 gateway@{host}",
        {"organizationName": "sj300-async"},
        [x509.UniformResourceIdentifier(application_uri), x509.DNSName(host)],
        [ExtendedKeyUsageOID.SERVER_AUTH, ExtendedKeyUsageOID.CLIENT_AUTH],
        days=GENERATED_DAYS,
    )
    for path in (certificate, private_key):
        path.parent.mkdir(mode=0o700, parents=True, exist_ok=True)
    descriptor = os.open(private_key, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    with os.fdopen(descriptor, "wb") as out:
        out.write(cert_gen.dump_private_key_as_pem(key))
    der = cert.public_bytes(serialization.Encoding.DER)
    if certificate.suffix.lower() == ".pem":
        der = cert.public_bytes(serialization.Encoding.PEM)
    certificate.write_bytes(der)


def load_or_generate(
    certificate: Path, private_key: Path, application_uri: str
) -> ServerCertificate:
    """The pair at these paths, generated first when neither exists.

    Raises:
        OSError: a file cannot be read or written.
        ValueError: a file is not a certificate or a key.
    """
    generated = not certificate.exists() and not private_key.exists()
    if generated:
        _generate(certificate, private_key, application_uri)
    return _load_pair(certificate, private_key, application_uri, generated=generated)


def _load_pair(
    certificate: Path, private_key: Path, application_uri: str, *, generated: bool
) -> ServerCertificate:
    cert = _load(certificate)
    serialization.load_pem_private_key(private_key.read_bytes(), password=None)
    uri = _uri_of(cert) or application_uri
    # OPC UA names a certificate by its SHA-1 thumbprint (what clients show to trust).
    thumbprint = cert.fingerprint(hashes.SHA1()).hex()
    return ServerCertificate(certificate, private_key, uri, generated, thumbprint)


def check_pair(certificate: Path, private_key: Path) -> str:
    """What a start would make of the pair, in words, without generating one
    (``sj300 gateway --check-config``).

    Raises:
        OSError: a file cannot be read, or a first start could not write the pair.
        ValueError: a file is not a certificate or a key.
    """
    if certificate.exists() or private_key.exists():  # the parser saw both or neither
        pair = _load_pair(certificate, private_key, "", generated=False)
        uri = f" for {pair.application_uri}" if pair.application_uri else ""
        return f"certificate {certificate}{uri}, thumbprint {pair.thumbprint}"
    for path in (certificate, private_key):  # in the order _generate writes them
        refusal = _refusal(path)
        if refusal is not None:
            raise refusal
    return f"certificate {certificate}: none yet, generated at the first start"


def _refusal(path: Path) -> OSError | None:
    """The error writing file *path* would meet, its directory made first as
    :func:`_generate` makes it (``mkdir(parents=True, exist_ok=True)``); None: none.

    As root every permission is granted; then only a file in the way is found.
    """
    directory = path.parent
    if directory.exists():
        if not directory.is_dir():
            return FileExistsError(errno.EEXIST, os.strerror(errno.EEXIST), str(directory))
        if not os.access(directory, os.W_OK | os.X_OK):
            return PermissionError(errno.EACCES, os.strerror(errno.EACCES), str(path))
        return None
    top, probe = directory, directory.parent
    while not probe.exists():
        top, probe = probe, probe.parent
    if not probe.is_dir():  # the first mkdir meets it: ENOTDIR, naming the directory
        return NotADirectoryError(errno.ENOTDIR, os.strerror(errno.ENOTDIR), str(directory))
    if not os.access(probe, os.W_OK | os.X_OK):  # the outermost mkdir is refused
        return PermissionError(errno.EACCES, os.strerror(errno.EACCES), str(top))
    return None


def free_port(host: str) -> int:
    """A port the system has free now (``port = 0``: the tests' way)."""
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    with socket.socket(family, socket.SOCK_STREAM) as probe:
        probe.bind((host, 0))
        port: int = probe.getsockname()[1]
        return port


def load_trusted(directory: Path) -> set[bytes]:
    """The DER bytes of every certificate in *directory* (DER or PEM files)."""
    trusted = set()
    for path in sorted(directory.iterdir()):
        if not path.is_file():
            continue
        data = path.read_bytes()
        try:
            if data.lstrip().startswith(b"-----BEGIN"):
                cert = x509.load_pem_x509_certificate(data)
            else:
                cert = x509.load_der_x509_certificate(data)
        except ValueError:
            _log.warning("opcua: %s is not a certificate; not trusted", path)
            continue
        trusted.add(uacrypto.der_from_x509(cert))
    return trusted
