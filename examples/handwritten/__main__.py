"""``python -m examples.handwritten`` serves the hand-written CartPole to one client."""

from examples.handwritten import main

main()
