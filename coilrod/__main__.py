"""``python -m coilrod``: the ``coilrod`` command line (see :mod:`coilrod.scene.cli`)."""

from .scene.cli import main

raise SystemExit(main())
