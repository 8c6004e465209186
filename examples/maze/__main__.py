"""``python -m examples.maze [--host H] [--port P]`` serves Maze."""

from examples.maze import main

main()
