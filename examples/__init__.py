"""Example environments shipped with rlenv.

One set of files under two names: in a checkout, ``examples`` (``python -m examples.NAME``,
``rlenv serve examples.cartpole:CartPoleEnvironment``); in an installed rlenv,
``rlenv.examples`` (``python -m rlenv.examples.NAME``,
``rlenv serve rlenv.examples.cartpole:CartPoleEnvironment``). The registered ids
(``rlenv/CartPole-v1`` ...) work in both. The examples import each other relatively, so each
loads under the name its package was imported by (:mod:`rlenv.targets`).
"""
