"""A swarm's cost: ``python benchmarks/swarm.py [--rounds R] [--steps S] [--json PATH]``.

The same as ``rlenv bench --swarm`` (:mod:`rlenv_tools._swarm_bench` says what is measured):
``examples/swarm`` of 16, 64 and 256 members served as one ``RLAgentGroup``, served as N
``RLAgent`` nodes, and in bare pymunk and numpy (the floor), rounds in turns. Prints for each N
``swarm N=256: group 123456 agent-steps/s, nodes 23456, floor 345678`` (medians), then
``swarm: group/nodes 5.3x, floor/group 1.8x at N=256``.
"""

import sys

from rlenv_tools.cli import main

if __name__ == "__main__":
    raise SystemExit(main(["bench", "--swarm", *sys.argv[1:]]))
