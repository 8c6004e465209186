"""``python -m rlenv_tools.inspector HOST:PORT ...``: the same as ``rlenv inspect``."""

import sys

from rlenv_tools.cli import main

raise SystemExit(main(["inspect", *sys.argv[1:]]))
