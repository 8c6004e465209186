"""``python -m examples.seeker [--host H] [--port P]`` serves the apple seeker."""

from examples.seeker import main

main()
