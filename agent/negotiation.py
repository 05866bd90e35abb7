"""Whom an nnQL agent asks for intents, so that it learns every intent it must wait for. Pure.

At each tick an nnQL agent waits for the intents of its higher-ranked neighbours within reach
(:func:`awaited`, by the one rule of ``protocol.ranks.waits_for``). It need not ask each of them:
an answer relays every intent its sender learned while negotiating (``protocol.messages.Answer``),
and that sender waited for *its* visible higher-ranked neighbours in turn. Positions are in the
observation, so an agent can tell exactly whom a neighbour sees, and so what its answer will bring.

:func:`plan_asks` walks the awaited neighbours from the lowest rank up (the nearest in the chain,
who decides last and knows the most) and asks each one that no earlier ask covers. When everyone
waits for everyone above it (the paper's presets on 11 x 11), that is one query, to the agent
ranked just above:
the negotiation becomes a chain of N - 1 answers a tick instead of N (N - 1) / 2, and every agent
knows exactly the intents it would have known by asking each neighbour. Should an answer lack an
intent it was expected to bring (its sender missed it, or died), the agent asks for the missing
ones directly (``agent.agent_node``). Why a chain: ``docs/design.md``.

Under the paper's ``reach`` rule an agent that has arrived still waits for the awaited intents,
although it needs none of them, so that it can relay them down the chain. Under ``meet`` nobody
waits for a parked agent: every observation that shows it says it is parked, so its intent,
STAY, is known (:func:`staying`), and it waits for nobody in turn. At an episode's end nobody
negotiates.

Each agent keeps a *standing* query open on the intent key of every agent near enough to be
asked soon (:func:`streamed`: within the interaction radius and a margin), and a decider answers
through it exactly the agents whose plan asks it (:func:`standing_answers`): the negotiation
then costs one message per planned ask, instead of a query, an answer and the query's end. A
decider ends the standing query of an agent that has not been that near for a while
(``agent.answering.STANDING_UNSEEN_TICKS``), so an agent holds the queries of the agents around
it, not of the swarm. A neighbour with no standing query open yet (one just come near) is asked
for the one tick (``?tick=T``). A decider can tell whose plan asks it when it sees every agent
its waiters wait for (:func:`plans_are_known`: on grids that fit in the view, or with a radius
of at most half the view); otherwise it answers every agent that waits for it, a superset of the
plans.
"""

from dataclasses import dataclass, field
from typing import Callable

from nnql_swarm.learning.neighbours import awaited_cells
from nnql_swarm.protocol.actions import VIEW_RADIUS, within
from nnql_swarm.protocol.config import NEGOTIATING_ALGOS, SwarmConfig
from nnql_swarm.protocol.messages import Observation
from nnql_swarm.protocol.ranks import awaits_answer, priority_rank, waits_for


def plan_asks(waiting_for: list[int], cells: dict[int, tuple[int, int]],
              rank: Callable[[int], int], radius: int, meet_only: bool) -> list[int]:
    """The fewest neighbours to ask, lowest-ranked first, whose answers (with what they relay)
    bring every intent of ``waiting_for``; ``cells`` holds each one's cell, ``rank`` its rank;
    ``radius`` and ``meet_only`` are the negotiation's (``protocol.ranks.waits_for``)."""
    ranked = sorted(((rank(j), j) for j in waiting_for), reverse=True)
    asks: list[int] = []
    covered: set[int] = set()
    for r, q in ranked:
        if q in covered:
            continue
        asks.append(q)
        covered.add(q)
        qx, qy = cells[q]
        covered.update(x for rx, x in ranked
                       if waits_for(True, r, rx, qx, qy, cells[x][0], cells[x][1], radius,
                                    meet_only))
    return asks


def plan_for(obs: Observation, config: SwarmConfig) -> tuple[list[int], list[int]]:
    """``(awaited, asks)`` for one observation: whose intents to learn, and whom to ask."""
    near = awaited_cells(obs, config)
    if not near:
        return [], []
    waiting_for = [j for j, _, _ in near]
    cells = {j: (x, y) for j, x, y in near}  # plan_asks reads only the cells of waiting_for
    tick, n = obs.tick, config.n_agents
    return waiting_for, plan_asks(waiting_for, cells, lambda j: priority_rank(j, tick, n),
                                  config.interaction_radius, config.meet_only)


STREAM_MARGIN = 4
"""How far beyond the interaction radius an agent keeps standing queries open (cells, Chebyshev):
two agents close in on each other by at most two cells a tick, so one that comes this near is
streamed a tick or two before it can be asked."""


def streamed(obs: Observation, config: SwarmConfig) -> list[tuple[int, int, int]]:
    """The agents of ``obs`` that the observing agent keeps a standing query open on, and whose
    standing queries on it it keeps: those within the interaction radius and
    :data:`STREAM_MARGIN` (at most the view), the only ones it can soon ask or be asked by."""
    reach = min(VIEW_RADIUS, config.interaction_radius + STREAM_MARGIN)
    x, y = obs.position
    return within(obs.neighbours, x, y, reach)


def plans_are_known(config: SwarmConfig) -> bool:
    """Whether a decider sees every agent that an agent within its reach waits for, and so can
    tell whose plan (:func:`plan_for`) asks it: the grid fits in the view, or twice the
    interaction radius does."""
    return (max(config.width, config.height) <= VIEW_RADIUS + 1
            or 2 * config.interaction_radius <= VIEW_RADIUS)


def standing_answers(obs: Observation, config: SwarmConfig) -> list[int]:
    """The agents that the agent which observed ``obs`` answers through their standing queries
    at this tick, the next in rank first: those whose plan asks it (:func:`plans_are_known`), or
    else every agent that waits for it (distance is symmetric: whoever is in reach)."""
    if config.algo not in NEGOTIATING_ALGOS or obs.episode_end:
        return []
    n, tick, radius, me = config.n_agents, obs.tick, config.interaction_radius, obs.agent
    meet, (x, y), rank = config.meet_only, obs.position, obs.rank
    if meet and obs.arrived and not config.step_aside:
        return []  # what awaits_answer says of every neighbour, without asking it
    waiters = sorted((r, j) for j, jx, jy in within(obs.neighbours, x, y, radius)
                     if (r := priority_rank(j, tick, n)) > rank  # only the lower-ranked wait
                     and awaits_answer(r, rank, jx, jy, x, y, radius, meet, j in obs.parked,
                                       False))
    if not waiters or not plans_are_known(config):
        return [j for _, j in waiters]
    parked = set(obs.parked)
    near = within(obs.neighbours, x, y, 2 * radius)  # the waiters and those they wait for
    cells = {j: (jx, jy) for j, jx, jy in near}
    ranks = {j: priority_rank(j, tick, n) for j in cells}
    cells[me], ranks[me] = (x, y), rank
    answered = []
    for w_rank, w in waiters:
        wx, wy = cells[w]
        waiting_for = [j for j, (jx, jy) in cells.items()
                       if ranks[j] < w_rank
                       and awaits_answer(w_rank, ranks[j], wx, wy, jx, jy, radius, meet, False,
                                         j in parked)]
        if me in plan_asks(waiting_for, cells, ranks.__getitem__, radius, meet):
            answered.append(w)
    return answered


@dataclass
class TickIntents:
    """What an agent has learned of one tick's intents: actions by agent, and who answered."""

    actions: dict[int, int] = field(default_factory=dict)
    answered: set[int] = field(default_factory=set)

    def add(self, sender: int, action: int, relayed, me: int) -> bool:
        """Record ``sender``'s answer and what it relays; False if it contradicts an intent
        already known (an announced intent never changes, so someone lied). The sender's own
        word wins over a relay of it."""
        consistent = self.actions.get(sender, action) == action
        consistent &= all(self.actions.get(other, a) == a
                          for other, a in relayed if other in self.answered)
        self.actions[sender] = action
        self.answered.add(sender)
        for other, a in relayed:
            if other != me:
                self.actions.setdefault(other, a)
        return consistent
