"""Negotiation ranks, and whom an agent waits for: one rule for agents, world, recording and sims.

The paper's hierarchical negotiation: at each tick every agent has a rank, 0 the highest, and
the ranks rotate every tick so that nobody always yields. An agent that reads intents waits, before
it decides, for the intent of every higher-ranked agent within the negotiation radius (Chebyshev
distance; the radius is the learner's interaction radius, since only those neighbours enter its
decision). Agents that wait for nobody decide in parallel. The agent process
(``agent.brain``), the world's recording of the negotiation (``world.viz``), the PettingZoo adapter
and the swarm simulator (``sim.swarm``) all ask :func:`waits_for`.
"""

from nnql_swarm.protocol.actions import chebyshev
from nnql_swarm.protocol.jit import kernel

SCRIPTED_RANK = -1
"""The rank of a scripted obstacle (the paper's experiment): above every learner, always."""


@kernel
def priority_rank(agent, tick, n_agents):
    """The agent's negotiation rank at a tick, 0 the highest; the order rotates every tick."""
    return (agent - tick) % n_agents


@kernel
def waits_for(reads_intents, rank, other_rank, x, y, other_x, other_y, radius):
    """Whether an agent of ``rank`` at ``(x, y)`` waits for the intent of the agent of
    ``other_rank`` at ``(other_x, other_y)`` before deciding."""
    return (reads_intents and other_rank < rank
            and chebyshev(x, y, other_x, other_y) <= radius)
