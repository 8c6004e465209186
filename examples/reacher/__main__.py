"""``python -m examples.reacher [--host H] [--port P]`` serves the reacher."""

from examples.reacher import main

main()
