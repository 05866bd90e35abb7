"""The world's kernels compiled ahead of time (``learning.ahead``): an extension module of its
own, beside the learning kernels' one, since the learning room cannot import the world's.

The world process runs its rules in plain Python (``protocol.jit``), where a step of 64 agents
took some 400 us of a tick in which every agent waits for the world, and the arbitration by
priority inheritance some 1,000 us more. Compiled so, the step (``world.step.world_move``) and the
arbitration (``world.pibt.plan``, under ``--arbitration pibt``) take a few microseconds each, the
same moves, the same results. So does the packing of every agent's neighbours for the
observations (``world.sight.pack_seen``).

    python -m nnql_swarm.world.rules_ahead     # build it (the launcher does, where it is missing)
"""

from nnql_swarm.learning.ahead import AheadModule
from nnql_swarm.world.pibt import PIBT_SIGNATURE, plan
from nnql_swarm.world.sight import SEEN_SIGNATURE, pack_seen
from nnql_swarm.world.step import MOVE_SIGNATURE, world_move

RULES = AheadModule("nnql_ahead_rules", {"world_move": (world_move, MOVE_SIGNATURE),
                                         "pibt_plan": (plan, PIBT_SIGNATURE),
                                         "pack_seen": (pack_seen, SEEN_SIGNATURE)},
                    __name__, "the world's rules")
"""The module of the world's step, its arbitration, and every agent's neighbours packed."""

if __name__ == "__main__":
    print(RULES.build())
