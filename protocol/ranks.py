"""Negotiation ranks, and whom an agent waits for: one rule for agents, world, recording and sims.

The paper's hierarchical negotiation: at each tick every agent has a rank, 0 the highest, and
the ranks rotate every tick so that nobody always yields. An agent that reads intents waits, before
it decides, for the intent of every higher-ranked agent within the negotiation radius (Chebyshev
distance; the radius is the learner's interaction radius, since only those neighbours enter its
decision). Agents that wait for nobody decide in parallel.

Under the ``meet`` wait rule (:data:`WAIT_RULES`) an agent waits only for those of them it could
meet on the next step: moving one cell up, down, left or right, two agents can enter one cell or
cross each other only when at most :data:`MEET_DISTANCE` moves apart (Manhattan). A neighbour
two cells away along both axes is within a radius of 2 but can reach none of the cells this agent
can, so its intent cannot make the two collide; the learner then reads it as one whose intent is
unknown. The agent process (``agent.brain``), the world's recording of the negotiation
(``recording.world``), the PettingZoo adapter and the swarm simulator (``sim.episode``) all ask
:func:`waits_for` whose intents an agent knows; whose answers it waits for on the wire,
:func:`awaits_answer` (the simulator has no wire).
"""

from nnql_swarm.protocol.actions import chebyshev
from nnql_swarm.protocol.jit import kernel

SCRIPTED_RANK = -1
"""The rank of a scripted obstacle (the paper's experiment): above every learner, always."""


@kernel
def priority_rank(agent, tick, n_agents):
    """The agent's negotiation rank at a tick, 0 the highest; the order rotates every tick."""
    return (agent - tick) % n_agents


WAIT_RULES = ("reach", "meet")
"""Whom an agent waits for, of the higher-ranked neighbours within the negotiation radius:
``reach``, every one (the paper's hierarchy); ``meet``, only those it could meet on the next
step (:func:`in_reach`)."""

MEET_DISTANCE = 2
"""Two agents one move each from a common cell, or from each other's, are at most this many
moves apart (Manhattan)."""


@kernel
def in_reach(x, y, other_x, other_y, radius, meet_only):
    """Whether an agent at ``(x, y)`` negotiates with a neighbour at ``(other_x, other_y)``:
    within ``radius`` (Chebyshev), and, where ``meet_only`` (the ``meet`` rule), one it could
    meet on the next step."""
    return (chebyshev(x, y, other_x, other_y) <= radius
            and (not meet_only or abs(other_x - x) + abs(other_y - y) <= MEET_DISTANCE))


@kernel
def waits_for(reads_intents, rank, other_rank, x, y, other_x, other_y, radius, meet_only):
    """Whether an agent of ``rank`` at ``(x, y)`` waits for the intent of the agent of
    ``other_rank`` at ``(other_x, other_y)`` before deciding."""
    return (reads_intents and other_rank < rank
            and in_reach(x, y, other_x, other_y, radius, meet_only))


@kernel
def awaits_answer(rank, other_rank, x, y, other_x, other_y, radius, meet_only, parked,
                  other_parked):
    """Whether an agent that reads intents waits for the other's answer before deciding: it
    waits for its intent (:func:`waits_for`) and, under ``meet``, neither has arrived on its goal
    (``parked``, ``other_parked``): an arrived agent's intent, STAY, is in every observation that
    shows it, and an arrived agent needs no intent."""
    return (not (meet_only and (parked or other_parked))
            and waits_for(True, rank, other_rank, x, y, other_x, other_y, radius, meet_only))
