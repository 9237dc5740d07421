"""``python -m sj300_async``: the ``sj300`` command line."""

from __future__ import annotations

from .cli import main

raise SystemExit(main())
