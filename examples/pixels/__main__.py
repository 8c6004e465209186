"""``python -m examples.pixels [--host H] [--port P]`` serves the pixels example."""

import sys

from examples.pixels import TARGET
from rlenv.cli import main

raise SystemExit(main(["serve", TARGET, *sys.argv[1:]]))
