"""``python -m examples.pixels [--host H] [--port P]`` serves the pixels example."""

from rlenv_tools.cli import serve_command

from . import TARGET

raise SystemExit(serve_command(TARGET))
