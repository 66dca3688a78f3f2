"""``python -m dtradar_rl`` -> :func:`dtradar_rl.cli.main`."""

from .cli import main

raise SystemExit(main())
