"""The OPC UA northbound: every drive as a typed object with units, timestamps and quality.

``[opcua] endpoint = "opc.tcp://HOST:PORT"`` or ``--opcua opc.tcp://HOST:PORT``
(the ``opcua`` extra: asyncua). One object per line (its bus counters) and
one per drive, named after OPC 40400 (UA for Powertrain) where the data
fits (:mod:`._model`); values with engineering units, source timestamps
and quality (:mod:`._quality`); subscriptions fed by the samples; methods
and writable parameters where the configuration grants them, through the
gateway's controller and lease (:mod:`._calls`); Basic256Sha256 with a
certificate generated at first start, users from the configuration
(:mod:`._security`, :mod:`._certificate`). docs/OPCUA.md is the
integrator's guide.

asyncua is imported only when the northbound is created: this package's
face is light, for the command line builds its flags from it.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Final

from .. import ConfigTable, Endpoint, Flag, Northbound, SectionContext
from ._config import (
    DEFAULT_SECURITY,
    OPCUA_KEYS,
    SECURITY_MODES,
    OpcuaConfig,
    certificate_error,
    parse_endpoint_url,
    parse_opcua_section,
)

__all__ = [
    "DEFAULT_SECURITY",
    "NORTHBOUND",
    "OPCUA_KEYS",
    "SECURITY_MODES",
    "OpcuaConfig",
    "parse_endpoint_url",
]


class _Spec:
    section = "opcua"
    keys = OPCUA_KEYS
    flag = Flag(
        "--opcua",
        "endpoint",
        "URL",
        "serve the drives over OPC UA at this endpoint (opc.tcp://HOST:PORT): typed values "
        "with units, timestamps and quality; Basic256Sha256",
    )
    requires = ("asyncua",)
    extra = "opcua"

    def parse(self, table: ConfigTable, context: SectionContext) -> OpcuaConfig:
        return parse_opcua_section(table, context)

    def endpoints(self, config: object) -> Sequence[tuple[str, Endpoint]]:
        assert isinstance(config, OpcuaConfig)
        return (("endpoint", config.endpoint),)

    def check(self, config: object) -> Sequence[str]:
        """What a start would make of the certificates (``--check-config``), loading them.

        Raises:
            GatewayStartError: the error a start would give.
        """
        from ._certificate import check_pair, load_trusted

        assert isinstance(config, OpcuaConfig)
        try:
            notes = [check_pair(config.certificate, config.private_key)]
        except (OSError, ValueError) as exc:
            raise certificate_error(config.certificate, exc) from None
        if config.trusted_clients is not None:
            trusted = load_trusted(config.trusted_clients)
            notes.append(f"{len(trusted)} trusted client certificate(s)")
        return notes

    def create(self, config: object) -> Northbound:
        from ._server import OpcuaServer

        assert isinstance(config, OpcuaConfig)
        return OpcuaServer(config)


#: The registry's entry (``sj300_async.gateway.opcua:NORTHBOUND``).
NORTHBOUND: Final = _Spec()
