"""``python -m examples.tag [--host H] [--port P]`` serves the chaser and its two runners."""

from rlenv_tools.cli import serve_command

from . import TARGET

raise SystemExit(serve_command(TARGET))
