"""``python -m validation [--fresh] [--only NAME ...] [--list]``: see :mod:`validation.run_all`."""

from .run_all import main

raise SystemExit(main())
