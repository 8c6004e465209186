"""``python -m examples.pusher [PORT]``: the pusher hosts itself, as a Godot project does."""

from . import main

main()
