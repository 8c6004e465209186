"""``python -m examples.plinko [--host H] [--port P]`` serves Plinko."""

from . import main

main()
