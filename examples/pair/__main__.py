"""``python -m examples.pair [--host H] [--port P]`` serves the two-agent pair."""

from rlenv_tools.cli import serve_command

from . import TARGET

raise SystemExit(serve_command(TARGET))
