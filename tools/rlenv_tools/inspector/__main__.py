"""``python -m rlenv_client.inspector HOST:PORT ...``: the same as ``rlenv inspect``."""

import sys

from rlenv.cli import main

raise SystemExit(main(["inspect", *sys.argv[1:]]))
