"""``python -m dtradar_data ...``: see :mod:`dtradar_data.cli`."""

from .cli import main

raise SystemExit(main())
