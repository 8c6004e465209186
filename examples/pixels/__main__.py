"""``python -m examples.pixels [--host H] [--port P]`` serves the pixels example."""

from examples.pixels import TARGET
from rlenv.cli import serve_command

raise SystemExit(serve_command(TARGET))
