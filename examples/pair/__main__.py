"""``python -m examples.pair [--host H] [--port P]`` serves the two-agent pair."""

from examples.pair import TARGET
from rlenv.cli import serve_command

raise SystemExit(serve_command(TARGET))
