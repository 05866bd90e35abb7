"""Whom an agent waits for, one rule for everyone (``protocol.ranks.waits_for``), and the
negotiation plan (``agent.negotiation``): whom to ask so as to learn every awaited intent."""

import itertools
import random

import numpy as np
import pytest

from nnql_swarm.agent import negotiation
from nnql_swarm.agent.negotiation import Planner
from nnql_swarm.agent.brain import AgentBrain
from nnql_swarm.protocol.actions import N_ACTIONS, RIGHT, STAY, sees, target_x, target_y
from nnql_swarm.protocol.config import ALGOS, SwarmConfig
from nnql_swarm.protocol.messages import WORLD_SENDER, Observation, pack_ids, pack_neighbours
from nnql_swarm.protocol.ranks import WAIT_RULES, priority_rank, waits_for
from nnql_swarm.recording.world import negotiation_pairs


def plan_for(obs: Observation, c: SwarmConfig) -> tuple[list[int], list[int]]:
    """Whom the agent that was sent ``obs`` waits for, and whom of them it asks."""
    plan = Planner(c)(obs)
    assert plan is not None, "these observations fit their runs"
    return plan.awaited, plan.asks


def standing_answers(obs: Observation, c: SwarmConfig) -> list[int]:
    """Whom the agent that was sent ``obs`` answers through their standing queries."""
    plan = Planner(c)(obs)
    assert plan is not None, "these observations fit their runs"
    return plan.answered


def config(n: int, algo: str = "nnql", radius: int = 10, wait_rule: str = "reach",
           on_target: str = "park") -> SwarmConfig:
    return SwarmConfig(n_agents=n, algo=algo, interaction_radius=radius, wait_rule=wait_rule,
                       on_target=on_target, width=40, height=40)


def observe(agent: int, tick: int, n: int, cells: dict[int, tuple[int, int]],
            episode_end: bool = False, arrived=(), parks: bool = True) -> Observation:
    """Agent ``agent``'s observation when the agents stand on ``cells`` (view radius 10), those
    of ``arrived`` on their goals (parked there, as the world says, if ``parks``)."""
    me = cells[agent]
    seen = tuple((j, x, y) for j, (x, y) in sorted(cells.items())
                 if j != agent and sees(*me, x, y))
    return Observation(run="neg", tick=tick, sender=WORLD_SENDER, agent=agent, episode=0, step=0,
                       position=me, goal=(0, 0), neighbours=pack_neighbours(seen),
                       rank=priority_rank(agent, tick, n), reward_ds=0.0, reward_ca=0.0,
                       collided=False, arrived=agent in arrived, episode_end=episode_end,
                       parked=pack_ids([j for j, _, _ in seen if j in arrived and parks]))


def learned(agent: int, tick: int, n: int, cells, asked_by: dict[int, list[int]]) -> set[int]:
    """Whose intents ``agent`` ends up knowing when everyone answers with what it learned."""
    known: set[int] = set()
    for j in asked_by[agent]:
        known |= {j} | learned(j, tick, n, cells, asked_by)
    return known


def test_everyone_in_view_makes_a_chain_of_one_query_each():
    n, tick = 8, 5
    cells = {i: (i, i % 3) for i in range(n)}
    for agent in range(n):
        waiting_for, asks = plan_for(observe(agent, tick, n, cells), config(n))
        rank = priority_rank(agent, tick, n)
        assert len(waiting_for) == rank
        assert asks == ([] if rank == 0 else [(agent - 1) % n])  # the one ranked just above


@pytest.mark.parametrize("wait_rule", WAIT_RULES)
@pytest.mark.parametrize("radius", [2, 10])
@pytest.mark.parametrize("seed", range(20))
def test_the_plan_covers_every_awaited_intent_on_sparse_grids(seed, radius, wait_rule):
    rng = random.Random(seed)
    n, tick = 12, rng.randrange(100)
    spots = rng.sample(list(itertools.product(range(40), range(12))), n)
    cells = dict(enumerate(spots))
    c = config(n, radius=radius, wait_rule=wait_rule)
    parked = set(rng.sample(range(n), 3))
    asked_by = {a: plan_for(observe(a, tick, n, cells, arrived=parked), c)[1]
                for a in cells}
    for agent in cells:
        waiting_for, asks = plan_for(observe(agent, tick, n, cells, arrived=parked), c)
        assert set(asks) <= set(waiting_for)
        assert set(waiting_for) <= learned(agent, tick, n, cells, asked_by)


def test_nobody_negotiates_for_ql_or_at_an_episode_end():
    cells = {0: (0, 0), 1: (1, 0)}
    assert plan_for(observe(1, 0, 2, cells), config(2)) == ([0], [0])
    assert plan_for(observe(1, 0, 2, cells), config(2, "ql")) == ([], [])
    assert plan_for(observe(1, 0, 2, cells, episode_end=True), config(2)) == ([], [])


@pytest.mark.parametrize("wait_rule", WAIT_RULES)
@pytest.mark.parametrize("radius,side", [(2, 40), (5, 40), (10, 11), (10, 40), (7, 30)])
@pytest.mark.parametrize("seed", range(10))
def test_standing_answers_go_to_exactly_the_plans_that_ask_them(seed, radius, side, wait_rule):
    """A decider answers by stream exactly the agents whose plan asks it, where it can tell
    (a grid in view, or a radius of at most half the view); elsewhere every agent that waits
    for it, a superset of the plans."""
    rng = random.Random(seed)
    n, tick = 12, rng.randrange(100)
    cells = dict(enumerate(rng.sample(list(itertools.product(range(side), range(side))), n)))
    c = SwarmConfig(n_agents=n, algo="nnql", interaction_radius=radius, wait_rule=wait_rule,
                    width=side, height=side)
    known = negotiation.plans_are_known(c)
    assert known == (radius <= 5 or side <= 11)
    parked = set(rng.sample(range(n), 3))
    plans = {a: plan_for(observe(a, tick, n, cells, arrived=parked), c) for a in cells}
    for p in cells:
        answered = standing_answers(observe(p, tick, n, cells, arrived=parked), c)
        expected = [a for a in cells if p in plans[a][1 if known else 0]]
        assert sorted(answered) == expected
        assert answered == sorted(answered, key=lambda a: priority_rank(a, tick, n))


@pytest.mark.parametrize("on_target", ["park", "step-aside"])
@pytest.mark.parametrize("wait_rule", WAIT_RULES)
@pytest.mark.parametrize("algo", [a for a in ALGOS if a != "oracle"])
@pytest.mark.parametrize("radius", [2, 10])
def test_the_agent_the_plan_and_the_recording_agree_on_whom_an_agent_waits_for(algo, radius,
                                                                               wait_rule,
                                                                               on_target):
    """One rule: the brain's neighbours to ask, the plan's awaited intents and the arrows the
    world records are the same pairs, for every algorithm and both on-target rules (the
    recording once drew none for nnql-dir while its agents waited)."""
    rng = random.Random(radius)
    n, c = 7, config(7, algo, radius, wait_rule, on_target)
    brains = [AgentBrain(i, c) for i in range(n)]
    waited = 0
    for tick in range(12):
        cells = dict(enumerate(rng.sample(list(itertools.product(range(14), range(14))), n)))
        arrived = [rng.random() < 0.2 for _ in range(n)]
        _, askers, asked_ones = negotiation_pairs(c, np.array([[cells[i] for i in range(n)]]),
                                                  np.array([arrived]), np.array([tick]))
        for i in range(n):
            obs = observe(i, tick, n, cells, arrived={j for j in range(n) if arrived[j]},
                          parks=not c.step_aside)
            asked = brains[i].neighbours_to_ask(obs, Planner(c)(obs).awaited)
            assert set(asked) == set(asked_ones[askers == i].tolist())
        waited += len(askers)
    assert (waited > 0) == (algo in ("nnql", "nnql-dir")), "only intent readers wait"


def test_tick_intents_prefer_the_senders_word_and_flag_contradictions():
    got = negotiation.TickIntents()
    assert got.add(3, 1, ((0, 2), (1, 4)), me=5)
    assert got.actions == {3: 1, 0: 2, 1: 4} and got.answered == {3}
    assert not got.add(1, 0, (), me=5)  # 1 says 0, 3 had relayed 4: the sender wins
    assert got.actions[1] == 0
    assert not got.add(2, 3, ((1, 4),), me=5)  # relays 4 for 1, whose own answer was 0
    assert got.actions[1] == 0
    assert got.add(4, 2, ((5, 1),), me=5)  # this agent's own intent is never taken from others
    assert 5 not in got.actions


def _can_meet(ax: int, ay: int, bx: int, by: int) -> bool:
    """Whether some pair of moves takes two agents into one cell or across each other (on a
    grid large enough that no edge is near)."""
    for a in range(N_ACTIONS):
        for b in range(N_ACTIONS):
            na = (target_x(ax, a, 99), target_y(ay, a, 99))
            nb = (target_x(bx, b, 99), target_y(by, b, 99))
            if na == nb or (na == (bx, by) and nb == (ax, ay)):
                return True
    return False


@pytest.mark.parametrize("radius", [0, 1, 2, 3, 10])
def test_the_meet_rule_waits_for_exactly_the_outranking_neighbours_that_could_collide(radius):
    """Under ``meet`` an agent waits for a higher-ranked neighbour within the radius exactly when
    some pair of next moves makes the two collide or swap; under ``reach``, for every one within
    the radius. Every offset of the view, from the middle of a large grid."""
    x = y = 50
    for dx, dy in itertools.product(range(-10, 11), repeat=2):
        if (dx, dy) == (0, 0):
            continue
        within = max(abs(dx), abs(dy)) <= radius
        assert waits_for(True, 3, 1, x, y, x + dx, y + dy, radius, False) == within
        assert (waits_for(True, 3, 1, x, y, x + dx, y + dy, radius, True)
                == (within and _can_meet(x, y, x + dx, y + dy)))
        assert not waits_for(True, 1, 3, x, y, x + dx, y + dy, radius, True)  # it outranks


def test_the_meet_rule_leaves_out_a_neighbour_two_cells_off_along_both_axes():
    cells = {0: (5, 5), 1: (7, 7), 2: (6, 6)}  # ranks at tick 0: 0, 1, 2
    reach = plan_for(observe(1, 0, 3, cells), config(3, radius=2))
    meet = plan_for(observe(1, 0, 3, cells), config(3, radius=2, wait_rule="meet"))
    assert reach[0] == [0] and meet[0] == []
    assert plan_for(observe(2, 0, 3, cells),
                                config(3, radius=2, wait_rule="meet"))[0] == [0, 1]


def test_under_the_meet_rule_nobody_waits_for_an_arrived_agent_and_it_waits_for_nobody():
    """An arrived agent stays: every observation that shows it says so, so its intent (STAY) is
    known without asking (``staying``), and it has nothing to relay. Under ``reach`` it is
    waited for, and waits, as in the paper's chain."""
    cells = {0: (5, 5), 1: (6, 5), 2: (6, 6)}  # ranks at tick 0: 0, 1, 2; all could meet
    meet, reach = config(3, radius=2, wait_rule="meet"), config(3, radius=2)
    obs = {a: observe(a, 0, 3, cells, arrived={1}) for a in cells}
    assert plan_for(obs[2], meet) == ([0], [0])
    assert Planner(meet)(obs[2]).staying == [1]
    assert plan_for(obs[1], meet) == ([], [])  # arrived: waits for nobody
    assert standing_answers(obs[1], meet) == []  # and nobody waits for it
    assert standing_answers(obs[0], meet) == [2]
    assert plan_for(obs[2], reach) == ([0, 1], [1])
    assert Planner(reach)(obs[2]).staying == []
    assert plan_for(obs[1], reach) == ([0], [0])  # to relay 0's intent to 2


@pytest.mark.parametrize("on_target", ["park", "step-aside"])
def test_an_arrived_agent_makes_way_only_when_it_may_step_aside(on_target):
    """Agent 1 stands on its goal; agent 0, ranked above it, announced moving right, into its
    cell. Parked, it stays (nobody may move into its cell); under step-aside it waits for 0's
    intent and steps off to a free cell, which is not 0's."""
    n, tick = 2, 0
    c = config(n, "nnql", 2, "reach", on_target)
    cells = {0: (5, 5), 1: (6, 5)}
    obs = observe(1, tick, n, cells, arrived={1}, parks=not c.step_aside)
    brain = AgentBrain(1, c)
    asked = brain.neighbours_to_ask(obs, Planner(c)(obs).awaited)
    action = brain.act(obs, {0: RIGHT} if asked else {})
    if not c.step_aside:
        assert (asked, action) == ([], STAY)
    else:
        assert asked == [0] and action != STAY
        assert (target_x(6, action, 40), target_y(5, action, 40)) not in {(5, 5), (6, 5)}
