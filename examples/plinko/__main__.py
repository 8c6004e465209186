"""``python -m examples.plinko [--host H] [--port P]`` serves Plinko."""

from examples.plinko import main

main()
