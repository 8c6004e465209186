"""``python -m examples.cartpole [--host H] [--port P]`` serves CartPole."""

from examples.cartpole import main

main()
