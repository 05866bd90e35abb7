"""Whom an nnQL agent asks for intents, so that it learns every intent it must wait for. Pure.

At each tick an nnQL agent waits for the intents of its higher-ranked neighbours within reach
(:attr:`Plan.awaited`, by the one rule of ``protocol.ranks.waits_for``). It need not ask each of them:
an answer relays every intent its sender learned while negotiating (``protocol.messages.Answer``),
and that sender waited for *its* visible higher-ranked neighbours in turn. Positions are in the
observation, so an agent can tell exactly whom a neighbour sees, and so what its answer will bring.

The plan (``learning.plan.asks_into``) walks the awaited neighbours from the lowest rank up (the nearest in the chain,
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
STAY, is known (:attr:`Plan.staying`), and it waits for nobody in turn. At an episode's end nobody
negotiates.

Each agent keeps a *standing* query open on the intent key of every agent near enough to be
asked soon (:attr:`Plan.near`: within the interaction radius and a margin), and a decider answers
through it exactly the agents whose plan asks it (:attr:`Plan.answered`): the negotiation
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

from nnql_swarm.learning.planner import STREAM_MARGIN, Plan, Planner, plans_are_known

__all__ = ["STREAM_MARGIN", "Plan", "Planner", "TickIntents", "plans_are_known"]


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
