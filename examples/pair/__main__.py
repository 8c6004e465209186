"""``python -m examples.pair [--host H] [--port P]`` serves the two-agent pair."""

import sys

from examples.pair import TARGET
from rlenv.cli import main

raise SystemExit(main(["serve", TARGET, *sys.argv[1:]]))
