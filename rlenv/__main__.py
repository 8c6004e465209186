"""``python -m rlenv`` is the ``rlenv`` command."""

from rlenv_tools.cli import main

raise SystemExit(main())
