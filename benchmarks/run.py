"""Run rlenv's benchmarks: ``python benchmarks/run.py [--json PATH]`` (same as ``rlenv bench``)."""

import sys

from rlenv_tools.cli import main

if __name__ == "__main__":
    raise SystemExit(main(["bench", *sys.argv[1:]]))
