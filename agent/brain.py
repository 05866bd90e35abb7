"""One swarm agent's decisions, pure: observation and neighbours' answers in, action out.

The agent process (``agent.node``) runs it; it calls the learner's kernel functions
(``agent.learner``) on Python lists and its tables' array, the very functions the swarm
simulator (``sim.swarm``) runs compiled, so that for the same seed the distributed swarm and the
simulator play the same run.

Negotiation: at every tick an agent that reads intents waits for the intents of its higher-ranked
neighbours within reach (``agent.negotiation.awaited``, by ``protocol.ranks.waits_for``; how it
learns them is that module's plan), and decides with those of them it needs
(:meth:`AgentBrain.neighbours_to_ask`), with whatever came back
(:meth:`AgentBrain.act`), and then answers for itself. A neighbour whose intent did not come is
read as one whose intent is unknown, from its current cell. A QL agent asks nobody.
"""

import numpy as np

from nnql_swarm.agent.learner import (
    LF_FIELDS, LP_READING, LS_PENDING, LS_TAKEN, NB_FIELDS, READ_DAQL, READINGS, REC_COUNT,
    REC_PAIRS, RF_FIELDS, ca_rows, decide, draw_noise, finish, learner_params, reach,
    record_outcome, record_size, state_size, write_updates,
)
from nnql_swarm.agent.known_map import (
    check_cell_order, fresh_map, known_cells, map_size, restore_known,
)
from nnql_swarm.protocol.actions import (
    N_ACTIONS, N_STATES, STAY, VIEW_RADIUS, sees, target_x, target_y, within,
)
from nnql_swarm.protocol.config import NEGOTIATING_ALGOS, SwarmConfig
from nnql_swarm.protocol.jit import floats, ints, python_values, rows
from nnql_swarm.protocol.messages import Observation
from nnql_swarm.protocol.ranks import in_reach
from nnql_swarm.protocol.seeding import AGENT_STREAM, stream_rng


class Learner:
    """One agent's tables and learner state as the kernel's buffers.

    The two tables are views of one array, ``Q_DS``'s rows first (:attr:`entries`, flat, is how
    a shared table's updates name its Q-values), a numpy array whether the kernel is compiled or
    not (``protocol.jit``); the other buffers are Python lists in plain Python, among them the
    walls it has seen and its way to its goal (``wmap``, ``agent.known_map``), which the agent
    derives from the run's map (``config.walls()``) and its own positions: the world sends no
    walls."""

    def __init__(self, config: SwarmConfig) -> None:
        reading = READINGS[config.algo]
        params, params_f = learner_params(config)
        self.params, self.params_f = ints(params), floats(params_f)
        both = np.full((N_STATES + ca_rows(reading, config.known_state), N_ACTIONS),
                       float(config.optimistic))
        self.q_ds, self.q_ca = both[:N_STATES], both[N_STATES:]
        self.entries = both.reshape(-1)  # entry e: row e // N_ACTIONS, action e % N_ACTIONS
        self.state = ints([0] * state_size(config.n_bodies))
        self.state_f = floats([0.0] * LF_FIELDS)
        self.rec = ints([0] * record_size(config.n_bodies))
        self.rec_f = floats([0.0] * RF_FIELDS)
        self.values = floats([0.0] * N_ACTIONS)
        self.width, self.height = config.width, config.height
        self.wmap = ints([0] * map_size(config.width, config.height))
        fresh_map(self.wmap)

    @property
    def actions_taken(self) -> int:
        return int(self.state[LS_TAKEN])

    def tables(self) -> tuple[np.ndarray, np.ndarray]:
        """``Q_DS`` and ``Q_CA`` as arrays (copies), for checkpoints and pictures."""
        return self.q_ds.copy(), self.q_ca.copy()

    def known_walls(self) -> list[int]:
        """The cells (``y * W + x``) of the walls this learner has seen (``agent.known_map``)."""
        return known_cells(self.wmap, self.width, self.height)

    def restore(self, q_ds: np.ndarray, q_ca: np.ndarray, actions_taken: int,
                known_walls=()) -> None:
        """Take the tables, count and known walls of a checkpoint (shapes checked by the
        caller)."""
        self.q_ds[:], self.q_ca[:] = q_ds, q_ca
        self.state[LS_TAKEN] = int(actions_taken)
        restore_known(self.wmap, [int(c) for c in known_walls], self.width, self.height)

    def forget_pending(self) -> None:
        """Drop the pending transition (its episode was abandoned, e.g. the world restarted)."""
        self.state[LS_PENDING] = 0

    def record(self) -> tuple[tuple[int, ...], tuple[float, float]]:
        """The learning record just written, as it travels: its integers and its two rewards."""
        ints = python_values(self.rec)
        return tuple(ints[:REC_PAIRS + 2 * ints[REC_COUNT]]), tuple(python_values(self.rec_f))


class NeighbourRows:
    """The learner's neighbour rows (``agent.learner.NB_*``) for an observation: what an agent
    reads its neighbours as, and what the world reads them as when it checks the agent's learning
    record (``world.records``)."""

    def __init__(self, config: SwarmConfig) -> None:
        self.config = config
        self.reads_intents = config.algo in NEGOTIATING_ALGOS
        self.reach = reach(config.interaction_radius)
        walls = config.walls().tolist()
        check_cell_order(walls)
        self._walls = {y * config.width + x: config.n_agents + k
                       for k, (x, y) in enumerate(walls)}
        self._walls_near: dict[tuple[int, int], list[tuple[int, int, int]]] = {}
        self.wall_x, self.wall_y = ints([x for x, _ in walls]), ints([y for _, y in walls])
        """The walls' cells, in cell order, as the known map reads them (``agent.known_map``)."""

    def __call__(self, obs: Observation, answers: dict[int, int], announcing: bool,
                 previous: dict[int, tuple[int, int]],
                 was_at: tuple[int, int] | None) -> list[list[int]]:
        """The visible neighbours within the learner's reach (``agent.learner.reach``: no other
        can change its decision or its learning) in id order, each with its announced move where
        it answered (``answers``), and its cell a tick ago where DAQL remembers it
        (``previous``); then the walls within reach, each known to stay where it is within the
        negotiation radius (as the simulator reads a scripted obstacle), unless nobody announces
        (``announcing``: not at an episode's end, nor once arrived), and seen a tick ago where
        the agent's cell then (``was_at``) saw it."""
        w, h = self.config.width, self.config.height
        parked = set(obs.parked)
        (x, y), far = obs.position, self.reach
        rows = []
        for j, jx, jy in within(obs.neighbours, x, y, far):
            action = answers.get(j)
            if action is None:
                nx, ny, known = jx, jy, 0
            else:
                nx, ny, known = target_x(jx, action, w), target_y(jy, action, h), 1
            px, py = previous.get(j, (-1, -1))
            rows.append([j, jx, jy, known, nx, ny, nx, ny, int(j in parked), px, py, 0])
        if self._walls:
            knows = announcing and self.reads_intents
            radius, meet = self.config.interaction_radius, self.config.meet_only
            for j, jx, jy in self._walls_within(x, y):
                px, py = (jx, jy) if was_at is not None and sees(*was_at, jx, jy) else (-1, -1)
                known = int(knows and in_reach(x, y, jx, jy, radius, meet))
                rows.append([j, jx, jy, known, jx, jy, jx, jy, 0, px, py, 0])
        return rows

    def _walls_within(self, x: int, y: int) -> list[tuple[int, int, int]]:
        """The walls within reach and view of cell ``(x, y)`` as ``(id, x, y)`` in id order
        (cell order), once per cell."""
        near = self._walls_near.get((x, y))
        if near is None:
            w, h, far = self.config.width, self.config.height, min(self.reach, VIEW_RADIUS)
            near = [(self._walls[cy * w + cx], cx, cy)
                    for cy in range(max(0, y - far), min(h, y + far + 1))
                    for cx in range(max(0, x - far), min(w, x + far + 1))
                    if cy * w + cx in self._walls]
            self._walls_near[(x, y)] = near
        return near


class AgentBrain:
    """An agent's learner, its noise, and what it remembers of its last observation.

    Where the swarm shares one table (``config.shared``), every agent holds a copy: its own
    learning record of a tick is not applied at once but goes out with its intent
    (:attr:`learned`); the world applies every agent's records of that tick to its own copy
    (``world.shared_table``) and hands everyone the entries they changed in the next
    observations, which each agent writes into its copy before it decides, so all copies stay
    equal (and equal to the simulator's one table).
    """

    def __init__(self, agent: int, config: SwarmConfig) -> None:
        if config.algo not in READINGS:
            raise ValueError(f"--algo {config.algo} plans centrally; run it with --in-process")
        if config.lookahead > 1:
            raise ValueError("a lookahead n > 1 is played by the simulator only (--in-process)")
        if config.step_aside:
            raise ValueError("--on-target step-aside is played by the simulator only "
                             "(--in-process)")
        self.agent = agent
        self.config = config
        self.learner = Learner(config)
        self.learned: tuple = ()  # this tick's learning record, for the intent (shared tables)
        self.rejected_updates = 0  # shared-table entries refused (outside, or uneven groups)
        self.reads_intents = config.algo in NEGOTIATING_ALGOS
        self.rng = stream_rng(config.seed, AGENT_STREAM, agent)
        self._random_actions = np.zeros(config.max_steps, dtype=np.int64)
        self._ties = np.zeros((config.max_steps, N_ACTIONS))
        self._noise: tuple[list[int], list[list[float]]] | None = None
        self._noise_episode = -1
        self._prepared = (-1, -1)  # the observation prepared last (episode, tick)
        self._seen: tuple = (-1, {}, None)  # DAQL: last tick's cells, and the agent's own
        self._was_at: tuple[int, int] | None = None  # DAQL: the agent's cell a tick ago
        self._rows = NeighbourRows(config)

    def neighbours_to_ask(self, obs: Observation, awaited: list[int]) -> list[int]:
        """The neighbours whose intents this agent decides with, of those it waits for
        (``awaited``, ``agent.negotiation.awaited``): none once it has arrived or at an
        episode's end, where it stays (it still waits, to relay them down the chain)."""
        if obs.arrived or obs.episode_end or not self.reads_intents:
            return []
        return awaited

    def prepare(self, obs: Observation) -> None:
        """What a decision on ``obs`` needs before the intents: the shared records applied, the
        episode's noise drawn (an agent prepares while it waits for its neighbours' intents)."""
        if self._prepared == (obs.episode, obs.tick):
            return
        self._prepared = (obs.episode, obs.tick)
        if self.config.shared and obs.updates:
            self.rejected_updates += write_updates(self.learner.entries, obs.updates)
        if obs.arrived or obs.episode_end or self._noise_episode == obs.episode:
            return
        draw_noise(self.rng, self._random_actions, self._ties)
        self._noise = (self._random_actions.tolist(), self._ties.tolist())
        self._noise_episode = obs.episode

    def act(self, obs: Observation, answers: dict[int, int]) -> int:
        """Learn from the last action's rewards and choose this tick's action (STAY if done)."""
        learner, shared = self.learner, self.config.shared
        self.prepare(obs)
        record_outcome(learner.state, learner.state_f, obs.reward_ds, obs.reward_ca, obs.arrived)
        (x, y), (gx, gy) = obs.position, obs.goal
        stops = obs.arrived or obs.episode_end
        near = self._neighbour_rows(obs, {} if stops else answers, not stops)
        nb, m = rows(near, NB_FIELDS), len(near)
        c, wx, wy = self.config, self._rows.wall_x, self._rows.wall_y
        if stops:
            written = finish(learner.q_ds, learner.q_ca, learner.params, learner.params_f,
                             learner.state, learner.state_f, learner.wmap, wx, wy, 0, len(wx),
                             obs.step == 0, x, y, gx, gy, nb, m, c.width, c.height, learner.rec,
                             learner.rec_f, not shared)
            action = STAY
        else:
            random_actions, ties = self._noise
            action, written = decide(
                learner.q_ds, learner.q_ca, learner.params, learner.params_f, learner.state,
                learner.state_f, learner.wmap, wx, wy, 0, len(wx), obs.step == 0, x, y, gx, gy,
                nb, m, c.width, c.height, random_actions[obs.step], floats(ties[obs.step]),
                learner.values, learner.rec, learner.rec_f, not shared)
        self.learned = (learner.record(),) if shared and written else ()
        return int(action)

    def _neighbour_rows(self, obs: Observation, answers: dict[int, int],
                        announcing: bool) -> list[list[int]]:
        """The learner's neighbour rows for this observation (:class:`NeighbourRows`), with
        DAQL's memory of the tick before."""
        previous = self._previous_cells(obs)
        return self._rows(obs, answers, announcing, previous, self._was_at)

    def _previous_cells(self, obs: Observation) -> dict[int, tuple[int, int]]:
        """DAQL's memory: the neighbours' cells at the previous tick of this episode, where they
        were in view, and the agent's own then (:attr:`_was_at`); and this tick's, for the next."""
        if self.learner.params[LP_READING] != READ_DAQL:
            return {}
        tick, cells, was_at = self._seen
        recent = tick == obs.tick - 1 and obs.step > 0
        self._was_at = was_at if recent else None
        self._seen = (obs.tick, {j: (jx, jy) for j, jx, jy in obs.neighbours}, obs.position)
        return cells if recent else {}
