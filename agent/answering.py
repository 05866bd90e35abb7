"""How an agent answers its neighbours' queries for its intent: the half of its machine
(``agent.agent_machine.AgentMachine``) that serves what others ask, pure as the rest of it.

A query for a decided tick is answered at once; one for a coming tick (at most
:data:`AHEAD_TICKS` past the decision) is held until the decision, and the held ones are then
answered the next in rank first; one for an older tick, or too far ahead, or one too many, is
refused with a reason and counted. A standing query (``?since=T;from=<id>``, one per asker: a
newer one replaces it) stays open and is answered at every decided tick whose plan asks this
agent, until its asker has not been near (``learning.planner.Plan.near``) for
:data:`STANDING_UNSEEN_TICKS` decided ticks: then this agent ends it (its asker, which opens one
on every agent near it, opens another when they come near again). So an agent holds the
standing queries of the agents around it, not of the whole swarm. The state lives on the
machine, which sets it; :class:`QueryAnswering` declares what it reads and writes: ``held``,
``standing``, ``standing_seen``, and the decided tick's ``decided_tick``, ``decided_answer``,
its ``decided_payload``, ``decided_waiters`` and ``decided_near``; and, for itself, when the
standing queries are next looked over for one to end (``standing_review_at``,
``standing_reviewed``).
"""

from nnql_swarm.protocol import keys
from nnql_swarm.protocol.config import priority_rank
from nnql_swarm.protocol.inbox import Inbox
from nnql_swarm.protocol.messages import Answer
from nnql_swarm.protocol.effects import EndQuery, Reply, ReplyError
from nnql_swarm.protocol.phase_machine import Machine, any_phase_input

MAX_HELD_QUERIES = 4 * 1024
"""Queries for the coming tick held at once; legitimately at most one per other agent."""

STANDING_UNSEEN_TICKS = 256
"""Decided ticks an asker may stay away before this agent ends its standing query. Every episode
places the agents anew, so streams kept over a few episodes serve the next ones: with 64 agents
(10 episodes of up to 60 steps, on the simulated network) 16 ticks made 32 queries a tick, 64
made 19, 256 made 7.6, about as many as one stream on every agent opened at the start (6.9); an
agent holds the streams of those that came near within these ticks, not the swarm's."""

AHEAD_TICKS = 2
"""How far past its last decision an agent holds queries and keeps answers: a neighbour that has
decided this tick may ask for, or answer, the next one before this agent decides this one."""


class QueryAnswering(Machine):
    """The inputs and steps of an agent's machine that answer the queries it receives."""

    agent: int
    n: int
    inbox: Inbox
    decided_tick: int  # -1 until a tick is decided
    decided_answer: Answer | None  # set with decided_tick
    decided_payload: bytes
    decided_waiters: list[int]  # whom the decided tick's answer goes to by stream
    decided_near: list[int]  # Plan.near at the decided tick
    held: list[tuple[int, int, int]]  # (tick, asker's rank, query)
    standing: dict[int, int]  # asker -> its standing query on this agent
    standing_seen: dict[int, int]  # asker -> the last decided tick it was near
    standing_review_at: int  # no standing query can end before this decided tick
    standing_reviewed: int  # the decided tick of the last look, to tell a world come back

    @any_phase_input
    def on_query(self, query: int, parameters, now: float) -> None:
        """A neighbour's query on this agent's intent key; ``parameters`` are its selector's
        (a str such as ``"tick=12;from=3"``, or anything ``protocol.keys`` parses)."""
        out = self._out
        if self.phase is self.FINAL:
            out.append(EndQuery(query))
            return
        tick = keys.parse_intent_query(parameters)
        since = keys.parse_standing_since(parameters) if tick is None else None
        if since is not None:
            self._standing_query(query, since, keys.parse_intent_asker(parameters))
        elif tick is None:
            self.inbox.reject("bad-query", f"?{parameters}")
            out.append(ReplyError(query, b"bad query: expected ?tick=T or ?since=T;from=A"))
            out.append(EndQuery(query))
        elif tick <= self.decided_tick:
            self._answer(tick, query)
        elif self.decided_tick >= 0 and tick > self.decided_tick + AHEAD_TICKS:
            self.inbox.reject("future-query", f"tick {tick}, decided {self.decided_tick}")
            out.append(ReplyError(query, b"future tick"))
            out.append(EndQuery(query))
        elif len(self.held) >= MAX_HELD_QUERIES:
            self.inbox.reject("query-flood", f"{len(self.held)} queries held")
            out.append(ReplyError(query, b"too many queries"))
            out.append(EndQuery(query))
        else:
            asker = keys.parse_intent_asker(parameters)
            order = self.n if asker is None else priority_rank(asker, tick, self.n)
            self.held.append((tick, order, query))

    @any_phase_input
    def on_reply_failed(self, query: int, now: float) -> None:
        """A reply to a standing query could not be sent: its asker is gone (it opens a new
        one if it comes back)."""
        for asker, held in list(self.standing.items()):
            if held == query:
                del self.standing[asker]
                self.standing_seen.pop(asker, None)
                self._out.append(EndQuery(query))

    def _standing_query(self, query: int, since: int, asker: int | None) -> None:
        """Keep a neighbour's standing query (one per asker: a newer one replaces it), and
        answer it at once if the tick it starts from is already decided."""
        out = self._out
        if asker is None or asker == self.agent or asker >= self.n:
            self.inbox.reject("bad-query", f"?since={since};from={asker}")
            out.append(ReplyError(query, b"bad standing query: expected ?since=T;from=<another "
                                         b"agent>"))
            out.append(EndQuery(query))
            return
        old = self.standing.pop(asker, None)
        if old is not None:
            out.append(EndQuery(old))
        self.standing[asker] = query
        last = self.standing_seen[asker] = max(since - 1, self.decided_tick)
        if last > self.decided_tick:  # from a tick ahead: counted from the next decision
            self.standing_review_at = -1
        else:
            self.standing_review_at = min(self.standing_review_at,
                                          last + STANDING_UNSEEN_TICKS + 1)
        if since <= self.decided_tick and asker in self.decided_waiters:
            self._out.append(self._decided_reply(query))

    def _answer_standing_queries(self) -> None:
        """Answer the standing queries owed at the decided tick, the next in rank first, and
        end those of askers away for :data:`STANDING_UNSEEN_TICKS`: looked over only from the
        first tick at which one can be (or after a world that came back replayed the ticks)."""
        standing, seen, out, tick = self.standing, self.standing_seen, self._out, self.decided_tick
        for asker in self.decided_waiters:
            query = standing.get(asker)
            if query is not None:
                out.append(self._decided_reply(query))
        for j in self.decided_near:
            if j in seen:
                seen[j] = tick
        replayed = tick < self.standing_reviewed  # a world that came back replays tick numbers
        self.standing_reviewed = tick
        if tick < self.standing_review_at and not replayed:
            return
        for asker, last in list(seen.items()):
            if last > tick:
                seen[asker] = tick
            elif tick - last > STANDING_UNSEEN_TICKS:
                del seen[asker]
                out.append(EndQuery(standing.pop(asker)))
        self.standing_review_at = min(seen.values(), default=tick) + STANDING_UNSEEN_TICKS + 1

    def _answer_held(self) -> None:
        """Answer what was asked for the decided tick, the next in rank first: its decision
        is the one the rest of the chain waits for."""
        tick = self.decided_tick
        due = sorted((h for h in self.held if h[0] <= tick), key=lambda h: h[1])
        self.held = [h for h in self.held if h[0] > tick]
        for held_tick, _, query in due:
            self._answer(held_tick, query)

    def _answer(self, tick: int, query: int) -> None:
        out = self._out
        if tick == self.decided_tick:
            out.append(self._decided_reply(query))
        else:
            self.inbox.reject("stale-query", f"tick {tick}, decided {self.decided_tick}")
            out.append(ReplyError(query, b"stale tick"))
        out.append(EndQuery(query))

    def _decided_reply(self, query: int) -> Reply:
        """The decided tick's answer to ``query``: only asked for once a tick is decided (the
        ticks queried are never negative)."""
        assert self.decided_answer is not None
        return Reply(query, self.decided_payload, self.decided_answer)

    def _drop_held(self) -> None:
        for _, _, query in self.held:
            self._out.append(EndQuery(query))
        self.held = []
