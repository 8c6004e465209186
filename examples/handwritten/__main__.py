"""``python -m examples.handwritten`` serves the hand-written CartPole to one client."""

from . import main

main()
