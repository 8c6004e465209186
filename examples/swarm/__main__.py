"""``python -m examples.swarm [--host H] [--port P]`` serves the flock (one group)."""

from rlenv_tools.cli import serve_command

from . import TARGET

raise SystemExit(serve_command(TARGET))
