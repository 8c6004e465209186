"""``python -m examples.seeker [--host H] [--port P]`` serves the apple seeker."""

from . import main

main()
