"""``python -m examples.maze [--host H] [--port P]`` serves Maze."""

from . import main

main()
