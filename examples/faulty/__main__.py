"""``python -m examples.faulty [--host H] [--port P]`` serves the faulty environment."""

from rlenv_tools.cli import serve_command

raise SystemExit(serve_command(f"{__package__}:FaultyEnvironment"))
