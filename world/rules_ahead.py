"""The world's step compiled ahead of time (``learning.ahead``): an extension module of its own,
beside the learning kernels' one, since the learning room cannot import the world's.

The world process runs its rules in plain Python (``protocol.jit``), where a step of 64 agents
took some 400 us of a tick in which every agent waits for the world. ``world.step.world_move``
compiled so takes it in a few microseconds, the same step, the same results.

    python -m nnql_swarm.world.rules_ahead     # build it (the launcher does, where it is missing)
"""

from nnql_swarm.learning.ahead import AheadModule
from nnql_swarm.world.step import MOVE_SIGNATURE, world_move

RULES = AheadModule("nnql_ahead_rules", {"world_move": (world_move, MOVE_SIGNATURE)}, __name__,
                    "the world's rules")
"""The module of the world's step."""

if __name__ == "__main__":
    print(RULES.build())
