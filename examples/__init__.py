"""Example environments shipped with rlenv; each runs with ``python -m examples.NAME``."""
