"""Environments for the per-client server's tests (``rlenv serve per_client_envs:...``)."""

from __future__ import annotations

from examples.cartpole import CartPoleEnvironment


class OnlyOneEnvironment(CartPoleEnvironment):
    """CartPole that refuses to be built twice in a process (an exhausted resource, say)."""

    built = 0

    def __init__(self) -> None:
        type(self).built += 1
        if type(self).built > 1:
            raise RuntimeError("only one of these fits in a process")
        super().__init__()
