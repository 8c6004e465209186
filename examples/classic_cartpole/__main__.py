"""``python -m examples.classic_cartpole [--host H] [--port P]`` serves gymnasium's CartPole-v1."""

from . import main

main()
