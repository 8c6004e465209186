"""``python -m examples.hunt [--host H] [--port P]`` serves the hunter and the prey that come and go."""

from rlenv_tools.cli import serve_command

from . import TARGET

raise SystemExit(serve_command(TARGET))
