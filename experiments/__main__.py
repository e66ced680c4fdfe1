"""``python -m experiments``: the same command line as the ``flowtest`` script."""

from __future__ import annotations

from .cli.cli import main

raise SystemExit(main())
