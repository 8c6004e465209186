"""``python -m examples.reacher [--host H] [--port P]`` serves the reacher."""

from . import main

main()
