"""A compromised agent's lie: its learning records teach the shared table that collisions pay.

Used by the fault schedules (``sim.distributed``, the ``forge`` fault) and by the real-process
test of a forging agent (``tests/forging_agent.py``): the agent plays honestly, but every record
it sends carries the collision-avoidance reward it did not get (:data:`world.rules.CA_REWARD`
for a collision, nothing without one), so that, believed, the swarm would learn to collide.
"""

from nnql_swarm.world.rules import CA_REWARD


def forged(record: tuple) -> tuple:
    """``record`` (integers, rewards) with its collision-avoidance reward turned round."""
    integers, (r_ds, r_ca) = record
    return integers, (r_ds, CA_REWARD - r_ca)
