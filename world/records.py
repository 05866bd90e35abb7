"""Whether a learning record is the one the agent's own transition wrote. Pure.

Where the agents share one table, each intent carries the sender's learning record of the tick
(``learning.learner``): Eq. 9's ``s, a, terminal, s'`` with the two rewards, and a pair of Q_CA rows
``(s_i, s'_i)`` per neighbour. The world saw the transition the record claims: what it sent the
agent at the tick it decided (its cell, goal and neighbours, who had arrived) and at the next
(where it ended up, its rewards, whether it arrived), the intent it announced, and every intent
of both ticks as the world heard them. :class:`RecordCheck` rebuilds the record from that with
the agent's own code (``learning.expected.expected_record``: the rows of
``learning.neighbours.neighbour_rows_into`` read and completed by ``learning.readings.read_rows``
and ``complete``, in one call compiled ahead of time), and compares.

What it cannot know is which of the intents an agent waited for reached it in time (a neighbour
whose answer did not come is read as one whose intent is unknown), nor, where the world missed
a neighbour's intent, what that intent was. The check first rebuilds the record as if every
awaited answer came (what a run without faults gives); should that differ, it accepts a record
whose every field the world knows is exactly its own, and whose every neighbour pair is one the
agent could have written: each awaited neighbour read as known (with its intent as the world
heard it, or any intent where the world missed it) or as unknown, and, for DAQL, a neighbour's
predicted move remembered or not. So everything is checked but, for each awaited neighbour, one
bit (heard or not), and for a neighbour whose intent the world missed, which move it announced.

A record is checked against the agent's decision at the tick before, which the world has only if
it heard the agent's intent then: a record with none to check against (the agent's intent before
was missed, or the world has just started or resumed) is refused too (:data:`UNCHECKED`), else a
silent tick would let any record through. An honest agent loses only such records, which a
faulty tick makes anyway.

Its cost: it reads only the neighbours a record names (those within the interaction radius at
the decision, and the same ones for ``s'``), and the rows an agent decided with at a tick are
those the check of its record of that tick read (kept for one tick), so a record costs one
reading of its neighbours and one ``complete``, in one compiled call; whom each agent waited for
and knew to stay, the world works out for every agent of a tick at once
(:meth:`RecordCheck.plan_tick`, ``learning.plan.world_plans``) when the tick's first record needs
them, not while every agent waits for the tick's observations (``bench/record_check.py``).
"""

from typing import NamedTuple

import msgspec
import numpy as np

from nnql_swarm.learning import ahead
from nnql_swarm.learning.expected import (
    E_COMPLETED, E_FIELDS, E_WRITTEN, complete_pending,
)
from nnql_swarm.learning.fields import (
    DS_GOAL, LF_FIELDS, LP_DS_REWARD, LP_DS_STATE, LP_READING, NB_FIELDS, NB_ID, NB_X, NB_Y,
    READ_DAQL, REC_GOAL, REC_NEXT_GOAL, REC_PAIRS, REWARD_WORLD, RF_FIELDS, RF_R_DS,
    learner_params, record_size, state_size,
)
from nnql_swarm.learning.plan import PLAN_PARTS, SCRATCH
from nnql_swarm.learning.planner import unpack_seen
from nnql_swarm.learning.readings import read_rows, uses_map
from nnql_swarm.learning.rows import NeighbourRows
from nnql_swarm.learning.tables import float_array, int_array
from nnql_swarm.protocol.actions import N_ACTIONS, STAY, chebyshev, within
from nnql_swarm.protocol.config import NEGOTIATING_ALGOS, SwarmConfig
from nnql_swarm.protocol.jit import python_values
from nnql_swarm.protocol.messages import (
    Observation, pack_neighbours, unpack_neighbours,
)

FORGED = "forged-record"
"""A record that is not the one the agent's transition wrote: refused, and the agent's later
records with it until the agent restarts."""
BARRED = "barred-record"
"""A record of an agent that sent a forged one since it last started: refused unchecked."""
UNCHECKED = "unchecked-record"
"""A record the world has no decision of the agent's to check against: refused."""


class Decision(NamedTuple):
    """What the world saw of one agent's decision at a tick: the observation it sent the agent,
    every agent's intent as it heard them (an action each, -1 where it missed it), and the
    agent's observation of the tick before (DAQL remembers its neighbours' cells then), if it was
    sent one."""

    obs: Observation
    intents: np.ndarray
    before: Observation | None


def _only(obs: Observation, neighbours) -> Observation:
    """``obs`` with only ``neighbours`` in view: the rows of the others are not needed (each
    neighbour's row is its own), and building them is most of a check's cost."""
    return msgspec.structs.replace(obs, neighbours=pack_neighbours(neighbours))


def _stops(obs: Observation, lifelong: bool) -> bool:
    """An agent that has arrived, or at an episode's end, decides nothing (``AgentBrain.act``);
    in a lifelong run an agent that reached its goal has its next one, and goes on."""
    return (obs.arrived and not lifelong) or obs.episode_end


def decides(obs: Observation, lifelong: bool) -> bool:
    """Whether an agent that was sent ``obs`` and announced an intent decided on it (and so left
    a transition for its next record)."""
    return not _stops(obs, lifelong)


class RecordCheck:
    """The records of one run's agents checked against the transitions the world saw. The
    intents it reads are arrays of an action per agent, -1 where the world did not hear it."""

    def __init__(self, config: SwarmConfig) -> None:
        self.config = config
        self.rows = NeighbourRows(config)
        self._expected, _ = ahead.KERNELS.compiled("expected_record")
        ints = int_array  # the kernel's buffers are arrays, compiled or not
        params, params_f = learner_params(config)
        self.params, self.params_f = ints(params), float_array(params_f)
        self.map_fields = bool(uses_map(self.params))
        if self.map_fields:  # destination seeking read on the agent's known map: see could_write
            self.params[LP_DS_STATE], self.params[LP_DS_REWARD] = DS_GOAL, REWARD_WORLD
        self.still_terminal = config.still_terminal
        self.lifelong = config.lifelong
        self.daql = bool(self.params[LP_READING] == READ_DAQL)
        self.radius = config.interaction_radius
        n, bodies, size = config.n_agents, config.n_bodies, self.rows.size
        self._no_map = ints([0])
        self._state, self._state_f = ints([0] * state_size(bodies)), np.zeros(LF_FIELDS)
        self._rec, self._rec_f = ints([0] * record_size(bodies)), np.zeros(RF_FIELDS)
        self._answer, self._prev_x, self._prev_y, self._keep = (ints([0] * n) for _ in range(4))
        self._scratch = np.zeros((size, NB_FIELDS), dtype=np.int64)  # rows read at a decision
        self._completed = np.zeros((size, NB_FIELDS), dtype=np.int64)
        self._counts = ints([0] * E_FIELDS)
        self._none, self._no_ids = np.zeros((0, 3), dtype=np.int64), ints([])
        self._plan_kernel, _ = ahead.KERNELS.compiled("world_plans")
        self._plan_scratch = np.zeros((SCRATCH, n + 1), dtype=np.int64)  # world_plans' buffers
        self._plan_out = np.zeros((PLAN_PARTS, n + 1), dtype=np.int64)
        self._plan_counts = np.zeros(PLAN_PARTS + 1, dtype=np.int64)
        self._tick_sights: dict[int, tuple] = {}  # tick -> what its plans are worked out from
        self._tick_plans: dict[int, tuple] = {}  # tick -> every agent's plan, once worked out,
        # and each agent's part of it as _negotiated took it
        self._parks = not config.step_aside  # arrived agents park: wait for nobody, and stay
        self._negotiates = config.algo in NEGOTIATING_ALGOS
        self._decided: dict[int, tuple] = {}  # agent -> (tick, its rows as it decided then)

    # What an agent could have heard, and read its neighbours as.

    def _answers(self, obs: Observation, intents, stops: bool) -> tuple[dict, list]:
        """The intents the agent decided with, had every awaited answer come (the arrived
        neighbours it knows stay, and each awaited one whose intent the world heard), and the
        awaited neighbours (any of which may not have answered in time)."""
        if stops:
            return {}, []
        waited, staying = (python_values(part) for part in self._negotiated(obs)[:2])
        known = {j: STAY for j in staying}
        known.update((j, int(intents[j])) for j in waited if intents[j] >= 0)
        return known, waited

    def plan_tick(self, tick: int, x: np.ndarray, y: np.ndarray, arrived: np.ndarray,
                  sees_all: bool, ending: bool) -> None:
        """Keep what the world reads of every agent's plan at ``tick``: the agents' cells and
        arrivals as the tick's observations show them (``SwarmWorld.sight``), for this tick and
        the next. The plans themselves (``learning.plan.world_plans``, every agent's at once) are
        worked out when a record first reads them (:meth:`_negotiated`), not as the tick's
        observations are sent: between the last intent of a tick and the next observations every
        agent waits for the world."""
        self._tick_sights[tick] = (x, y, arrived, sees_all, ending)
        self._tick_sights.pop(tick - 2, None)
        self._tick_plans.pop(tick - 2, None)

    def _plans(self, tick: int) -> tuple[tuple, dict[int, tuple]]:
        """Every agent's plan at ``tick`` (:meth:`plan_tick`), worked out at the first call,
        and the agents' parts of it taken so far (:meth:`_negotiated`)."""
        plans = self._tick_plans.get(tick)
        if plans is None:
            sight = self._tick_sights.pop(tick, None)
            assert sight is not None, f"tick {tick} checked without its plans"
            plans = self._tick_plans[tick] = (self._world_plans(tick, *sight), {})
        return plans

    def _world_plans(self, tick: int, x: np.ndarray, y: np.ndarray, arrived: np.ndarray,
                     sees_all: bool, ending: bool) -> tuple:
        config, n = self.config, self.config.n_agents
        nbs, parkeds = np.empty((n, n, 3), dtype=np.int64), np.empty((n, n), dtype=np.int64)
        awaited, staying = np.empty((n, n), dtype=np.int64), np.empty((n, n), dtype=np.int64)
        ks, ps, n_awaited, n_staying = (np.empty(n, dtype=np.int64) for _ in range(4))
        self._plan_kernel(x, y, arrived, n, sees_all, self._parks, tick, config.width,
                          config.height, self.radius, config.meet_only, self._parks,
                          self._negotiates and not ending, nbs, ks, parkeds, ps,
                          self._plan_scratch, self._plan_out, self._plan_counts, awaited,
                          n_awaited, staying, n_staying)
        return (nbs, ks.tolist(), parkeds, ps.tolist(), awaited, n_awaited.tolist(), staying,
                n_staying.tolist())

    def _negotiated(self, obs: Observation) -> tuple:
        """Whom the agent waits for at ``obs`` and the arrived neighbours it knows stay
        (``agent.negotiation``), as arrays, with its neighbours ``(k, 3)`` and parked ids as
        the plan read them: from the plans of its tick (:meth:`plan_tick`), which the world
        keeps while a record may read them; each agent's taken once (a record reads its
        agent's of its tick, and of the tick before, which the record before read)."""
        i = obs.agent
        plans, taken = self._plans(obs.tick)
        plan = taken.get(i)
        if plan is None:
            nbs, ks, parkeds, ps, awaited, n_awaited, staying, n_staying = plans
            plan = taken[i] = (awaited[i, :n_awaited[i]], staying[i, :n_staying[i]],
                               nbs[i, :ks[i]], parkeds[i, :ps[i]])
        return plan

    def ready(self, obs: Observation, intents) -> bool:
        """Whether ``intents`` (the tick's so far) hold every intent the agent that was sent
        ``obs`` may have decided with: then its record can be checked before the tick closes."""
        if _stops(obs, self.lifelong):
            return True
        awaited = self._negotiated(obs)[0]
        return len(awaited) == 0 or min(intents[awaited].tolist()) >= 0  # a third of .min()

    def _memories(self, obs: Observation, before: Observation | None, sure: bool) -> list:
        """DAQL's memories of the tick before, ``(previous cells, own cell then)``: those of
        ``before`` where it is that tick's of the same episode, and none; the first only, where
        the agent surely took ``before`` (``sure``). Nothing to remember for the other readings."""
        if not self.daql:
            return [({}, None)]
        options: list[tuple[dict[int, tuple[int, int]], tuple[int, int] | None]] = []
        if self._remembers(obs, before):
            assert before is not None
            cells = unpack_neighbours(before.neighbours).tolist()
            options.append(({j: (x, y) for j, x, y in cells}, before.position))
        if not (sure and options):
            options.append(({}, None))
        return options

    def _remembers(self, obs: Observation, before: Observation | None) -> bool:
        """Whether DAQL, at ``obs``, remembers ``before``: that tick's, of the same episode."""
        return (self.daql and before is not None and before.tick == obs.tick - 1
                and obs.step > 0)

    def _read(self, obs: Observation, answers: dict, stops: bool, memory) -> list[list[int]]:
        """The neighbour rows with their Q_CA rows read (``NB_ROW``), as the agent reads them."""
        near = self.rows(obs, answers, not stops, *memory)
        x, y = obs.position
        read_rows(self.params, x, y, near, len(near))
        return [list(row) for row in python_values(near)] if len(near) else []

    # The record.

    def expected(self, decision: Decision, obs: Observation,
                 intents) -> tuple[tuple[int, ...], tuple[float, ...]]:
        """The record the agent's transition from ``decision`` to ``obs`` writes, had every
        awaited answer come at both ticks (``intents``: this tick's, as the world heard them):
        ``learning.expected.expected_record``, the rows the agent decided with read at the last
        record's completion where it was checked then."""
        before, config, counts = decision.obs, self.config, self._counts
        (bx, by), (bgx, bgy), (ox, oy), (ogx, ogy) = before.position, before.goal, obs.position, \
            obs.goal
        b_awaited, b_staying, b_nb, b_parked = self._negotiated(before)
        known = self._decided.get(before.agent)
        if known is not None and known[0] == before.tick:
            decided, n_decided = known[1], len(known[1])  # every intent then was in
        else:
            decided, n_decided = self._scratch, -1
        memory, was_x, was_y, mem_k = self._none, -1, -1, 0
        if self._remembers(before, decision.before):
            assert decision.before is not None
            memory = unpack_seen(decision.before, True)[0]
            (was_x, was_y), mem_k = decision.before.position, len(memory)
        stops = _stops(obs, self.lifelong)
        if stops:
            awaited, staying = self._no_ids, self._no_ids  # it waits for nobody
            nb, parked = unpack_seen(obs, True)
        else:
            awaited, staying, nb, parked = self._negotiated(obs)
        rows = self.rows
        self._expected(self.params, self.params_f, self._state, self._state_f, self._no_map,
                       self._rec, self._rec_f, config.width, config.height, config.n_agents,
                       self.radius, rows.reach, config.meet_only, rows.reads_intents,
                       rows.wall_ids, rows.n_walls, rows.wall_far, self.map_fields,
                       self.still_terminal, b_nb, len(b_nb), b_parked, len(b_parked), bx, by,
                       bgx, bgy, int(decision.intents[before.agent]), decision.intents,
                       b_awaited, len(b_awaited), b_staying, len(b_staying), memory, mem_k,
                       was_x, was_y, decided, n_decided, nb, len(nb), parked, len(parked), ox,
                       oy, ogx, ogy, obs.reward_ds, obs.reward_ca, obs.arrived, stops, intents,
                       awaited, len(awaited), staying, len(staying),
                       self._remembers(obs, before), self._answer, self._prev_x, self._prev_y,
                       self._keep, self._completed, counts)
        if not stops:
            self._decided[obs.agent] = (obs.tick, self._completed[:counts[E_COMPLETED]].copy())
        return (tuple(self._rec[:counts[E_WRITTEN]].tolist()), tuple(self._rec_f.tolist()))

    def _complete(self, decision: Decision, obs: Observation, pending, completed):
        """``learning.expected.complete_pending``: the agent's pending transition from its
        decision (``pending``: the rows it decided with) completed with the neighbour rows of
        ``obs`` (``completed``)."""
        before = decision.obs
        (bx, by), (bgx, bgy), (ox, oy), (ogx, ogy) = before.position, before.goal, obs.position, \
            obs.goal
        written = complete_pending(
            self.params, self.params_f, self._state, self._state_f, self._no_map, bx, by, bgx,
            bgy, int(decision.intents[before.agent]), pending, len(pending), self.radius,
            obs.reward_ds, obs.reward_ca, obs.arrived, ox, oy, ogx, ogy, completed,
            len(completed), self.config.width, self.config.height, self.map_fields,
            self.still_terminal, self._rec, self._rec_f)
        return tuple(python_values(self._rec[:written])), tuple(python_values(self._rec_f))

    def _readings(self, obs: Observation, intents, stops: bool, before: Observation | None,
                  sure: bool, neighbour: int) -> list[list[int]]:
        """Every row the agent could have read ``neighbour`` as at ``obs`` (none if it was out
        of its rows): heard or not where awaited, with the intent the world heard or, where it
        missed it, any; each DAQL memory."""
        known, waited = self._answers(obs, intents, stops)
        choices = [dict(known)]
        if neighbour in waited:
            choices = [{k: a for k, a in known.items() if k != neighbour}]
            heard = int(intents[neighbour])
            moves = range(N_ACTIONS) if heard < 0 else (heard,)
            choices += [{**choices[0], neighbour: a} for a in moves]
        found = []
        for answers in choices:
            for memory in self._memories(obs, before, sure):
                for row in self._read(obs, answers, stops, memory):
                    if row[NB_ID] == neighbour and row not in found:
                        found.append(row)
        return found

    def could_write(self, record, decision: Decision, obs: Observation, intents) -> bool:
        """Whether the agent could have written ``record`` for the transition from ``decision``
        to ``obs`` (``intents``: this tick's, as the world heard them), whichever awaited
        answers reached it (see the module docstring)."""
        integers, values = record
        expected = self.expected(decision, obs, intents)
        if self.map_fields:
            expected = _map_fields_taken(expected, integers, values)
        if (tuple(integers), tuple(values)) == expected:
            return True
        if tuple(integers[:REC_PAIRS]) != expected[0][:REC_PAIRS] or tuple(values) != expected[1]:
            return False
        before = decision.obs
        (x, y), radius = before.position, self.radius
        near = within(unpack_neighbours(before.neighbours).tolist(), x, y, radius)
        rows_before = self._read(_only(before, near), {},
                                 False, ({}, None))
        pending = [row[NB_ID] for row in rows_before
                   if chebyshev(x, y, row[NB_X], row[NB_Y]) <= radius]
        if len(integers) != REC_PAIRS + 2 * len(pending):
            return False
        for k, neighbour in enumerate(pending):
            pair = (integers[REC_PAIRS + 2 * k], integers[REC_PAIRS + 2 * k + 1])
            if pair not in self._pairs(decision, obs, intents, neighbour):
                return False
        return True

    def _pairs(self, decision: Decision, obs: Observation, intents, neighbour: int) -> set:
        """Every ``(s_i, s'_i)`` pair the agent could have written for ``neighbour``."""
        before = decision.obs
        stops = _stops(obs, self.lifelong)
        pairs = set()
        for row in self._readings(before, decision.intents, False, decision.before, False,
                                  neighbour):
            after: list[list[int] | None] = list(
                self._readings(obs, intents, stops, before, False, neighbour))
            for following in after or [None]:
                completed = self._rows_of([] if following is None else [following])
                rec = self._complete(decision, obs, self._rows_of([row]), completed)
                pairs.add(rec[0][REC_PAIRS:REC_PAIRS + 2])
        return pairs

    @staticmethod
    def _rows_of(rows: list[list[int]]) -> np.ndarray:
        return np.array(rows, dtype=np.int64).reshape(len(rows), NB_FIELDS)


def _map_fields_taken(expected, integers, values):
    """``expected`` with destination seeking's states and reward as the record gives them: read
    on the agent's known map (``learning.known_map``: the walls it saw in its run, the arrived agents it
    saw in the episode), which the world does not follow, they are checked only to fit the
    table (``SharedTable.accepts``)."""
    ints_, floats_ = list(expected[0]), list(expected[1])
    if len(integers) > REC_NEXT_GOAL and len(values) > RF_R_DS:
        ints_[REC_GOAL], ints_[REC_NEXT_GOAL] = integers[REC_GOAL], integers[REC_NEXT_GOAL]
        floats_[RF_R_DS] = values[RF_R_DS]
    return tuple(ints_), tuple(floats_)
