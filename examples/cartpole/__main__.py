"""``python -m examples.cartpole [--host H] [--port P]`` serves CartPole."""

from . import main

main()
