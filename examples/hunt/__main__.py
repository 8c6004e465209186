"""``python -m examples.hunt [--host H] [--port P]`` serves the hunter and its prey."""

from rlenv_tools.cli import serve_command

from . import TARGET

raise SystemExit(serve_command(TARGET))
