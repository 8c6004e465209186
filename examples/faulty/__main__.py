"""``python -m examples.faulty [--host H] [--port P]`` serves the faulty environment."""

import sys

from rlenv.cli import main

raise SystemExit(main(["serve", "examples.faulty:FaultyEnvironment", *sys.argv[1:]]))
