"""``python -m rlenv`` is the ``rlenv`` command."""

from rlenv.cli import main

raise SystemExit(main())
