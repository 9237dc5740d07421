"""``sj300 gateway``: one process owns the lines, polls the drives and serves them.

Modbus TCP for SCADA (pymodbus's server under the gateway's own register
map), Prometheus metrics and a health check over HTTP, and a control lease
so that a controller that disappears does not leave a motor running. Needs
the ``gateway`` extra (``pip install 'sj300-async[gateway]'``). The user's
view is docs/GATEWAY.md.
"""

from __future__ import annotations
