"""Priority inheritance (PIBT), once: the oracle's planner and the world's ``--arbitration pibt``.

Two sources of preference, one planner (:func:`plan`). The oracle, a reference planner that knows
every goal, orders each agent's cells by their distance to its goal; under ``--arbitration pibt``
each agent announces its own order (``learning.learner.preference_ranks``: the length of the way
on the map it knows, then its learned values) and the world (``world.arbiter``; the simulator,
``sim.episode``) settles the tick by the same machinery. Either way no two agents are planned into
one cell and no two swap, so nobody collides.

Priority Inheritance with Backtracking (Okumura et al., 2022), one step at a time, on the world's
rules: agents in priority order (at the start, the longest shortest path to its goal first, then
by id; an agent gains a unit of priority at each step that finds it no nearer its goal than it
has ever been, as PIBT's priorities grow while an agent is not home) each take the free
neighbouring cell nearest their goal (breadth-first distances on the grid's free cells, around the
walls and the arrived agents); an agent that wants a cell someone still occupies makes that one
move first (it inherits the priority) and tries its next cell if it cannot. No two agents are
planned into one cell and no two swap, so the world's arbitration never finds a collision.
Walls are obstacles that never move. Arrived agents follow the world's on-target rule
(``world.rules``):

- ``park``: they are parked obstacles, and an agent next to its goal does not take it while
  parking there would leave another agent no way to its own. Where walls make corridors this
  does not always bring every agent home (two agents in a corridor one cell wide, the way out
  for one to back out, which PIBT one step at a time does not plan).
- ``step-aside``: PIBT as published. An agent on its goal is pushed like any other (it then
  inherits the pusher's priority and takes another cell, and comes back); an agent's priority
  grows by a grid's worth of cells at every step it ends off its goal, and falls back to 0 on
  it, so whoever has waited longest goes first; ties between cells at one distance break by a
  tie-breaker that changes every step (the published one is random). And LaCAM's swap
  (Okumura, 2023): two agents that must trade places in a corridor or a dead end walk out of it,
  one pulling the other, until there is room to pass.

The oracle learns nothing. It is a reference planner, not a lower bound: PIBT's paths are not
optimal. The lower bound is ``shortest_sum``, each agent's shortest path alone. Under
``--arbitration pibt`` it is also the baseline the field asks of a learned method, "PIBT with
greedy actions" (PIBT-greedy): the same arbitration, preferences by distance alone.
"""

from nnql_swarm.protocol.actions import N_ACTIONS, STAY, target_x, target_y
from nnql_swarm.protocol.jit import kernel

TIES = 1024
"""Tie-breakers per distance under ``step-aside`` (:func:`_tie`)."""

FAR = 1 << 30
"""The distance of a cell its agent cannot reach."""

UNWANTED = N_ACTIONS
"""The rank of a move an agent does not offer (``plan``'s ``ranks``): a missed intent offers only
STAY."""


@kernel
def goal_distances(goal_x, goal_y, blocked, width, height, distance, base, queue):
    """Breadth-first moves to the goal from every cell (``distance[base + cell]``; ``FAR`` where
    unreachable), around the cells marked in ``blocked``; ``queue``: one slot per cell."""
    cells = width * height
    for c in range(cells):
        distance[base + c] = FAR
    start = goal_y * width + goal_x
    distance[base + start] = 0
    queue[0] = start
    head, tail = 0, 1
    while head < tail:
        c = queue[head]
        head += 1
        x, y = c % width, c // width
        for a in range(N_ACTIONS - 1):
            nx, ny = target_x(x, a, width), target_y(y, a, height)
            nc = ny * width + nx
            if nc != c and distance[base + nc] == FAR and blocked[nc] == 0:
                distance[base + nc] = distance[base + c] + 1
                queue[tail] = nc
                tail += 1


@kernel
def _push(root, x, y, width, height, distances, occupant, reserved, decided, actions, stack,
          tried, swap, blocked, goal_x, goal_y, n, swapper, first, step, learned, ranks):
    """PIBT from agent ``root``, without recursion: ``stack`` holds the chain of agents pushed so
    far (each pushed by the one below it), ``tried`` each one's candidate moves tried (bits). An
    agent takes the untried free cell nearest its goal; if someone undecided stands there, that
    one is pushed next; if a pushed agent finds nothing, it stays and the one below tries its next
    cell; the first agent that finds a free cell settles the whole chain.

    With ``learned``, an agent's order over its cells is its own (``ranks[i * N_ACTIONS + a]``:
    0 for its first choice; :data:`UNWANTED` for a move it does not offer, which is never tried)
    instead of the distance to its goal.

    With ``swap`` (the ``step-aside`` rule's planner), cells at one distance are tried in the
    order of :func:`_tie` at ``step``, and (walls ``blocked``, goals, ``n`` agents; scratch
    ``swapper``, ``first``, a slot per chain level) the swap of LaCAM's PIBT (Okumura, 2023): where an agent and the one
    in its way must trade places and cannot on the spot (a corridor, a dead end), it tries its
    cells farthest from its goal first and, when it takes the first, pulls that one into the cell
    it leaves, until they reach room to pass."""
    cells = width * height
    decided[root] = True
    stack[0] = root
    tried[0] = 0
    top = 0
    while top >= 0:
        i = stack[top]
        parent = stack[top - 1] if top > 0 else -1
        here = y[i] * width + x[i]
        if swap and tried[top] == 0:
            swapper[top] = _swap_partner(i, x, y, width, height, distances, occupant, decided,
                                         blocked, goal_x, goal_y, n)
        far = swap and swapper[top] >= 0
        pushed = False
        settled = False
        while True:
            best_a, best_d = -1, FAR + 1
            if swap:
                best_d = (FAR + 1) * TIES
            if far:
                best_d = -1
            for a in range(N_ACTIONS):
                if (tried[top] >> a) & 1:
                    continue
                c = target_y(y[i], a, height) * width + target_x(x[i], a, width)
                if a != STAY and c == here:
                    continue
                if swap and blocked[c] != 0:
                    continue
                if learned:
                    d = ranks[i * N_ACTIONS + a]
                    if d >= UNWANTED:
                        continue
                else:
                    d = distances[i * cells + c]
                    if swap:
                        d = d * TIES + _tie(i, c, step)
                if (d > best_d) if far else (d < best_d):
                    best_a, best_d = a, d
            if best_a < 0:  # no cell left: it stays, and the agent below tries its next one
                reserved[here] = i
                actions[i] = STAY
                break
            if swap:
                first[top] = 1 if tried[top] == 0 else 0
            tried[top] |= 1 << best_a
            c = target_y(y[i], best_a, height) * width + target_x(x[i], best_a, width)
            if reserved[c] >= 0 or (parent >= 0 and c == y[parent] * width + x[parent]):
                continue
            reserved[c] = i
            actions[i] = best_a
            k = occupant[c]
            if k >= 0 and k != i and not decided[k]:
                decided[k] = True
                stack[top + 1] = k
                tried[top + 1] = 0
                pushed = True
            else:
                settled = True
            break
        if pushed:
            top += 1
        elif settled:
            if swap:  # each agent of the chain that took its first cell pulls its partner
                for level in range(top, -1, -1):
                    _pull(stack[level], swapper[level], first[level], x, y, width, height,
                          reserved, decided, actions)
            return
        else:
            top -= 1


@kernel
def _tie(i, c, step):
    """A tie-breaker among cells at one distance, which changes with the step (published PIBT
    breaks ties at random; a fixed order lets two agents trade a cell back and forth)."""
    return ((i + 1) * 73856093 ^ (c + 1) * 19349663 ^ (step + 1) * 83492791) % TIES


@kernel
def _pull(i, j, took_first, x, y, width, height, reserved, decided, actions):
    """The swap's pull: ``j``, undecided, into the cell ``i`` leaves, if nobody takes it."""
    if j < 0 or took_first == 0 or decided[j] or actions[i] == STAY:
        return
    here = y[i] * width + x[i]
    if reserved[here] >= 0:
        return
    for a in range(N_ACTIONS - 1):
        if target_y(y[j], a, height) * width + target_x(x[j], a, width) == here:
            reserved[here] = j
            actions[j] = a
            decided[j] = True
            return


@kernel
def _way_out(c, avoid, width, height, blocked, occupant, goal_x, goal_y, n):
    """The cells an agent at ``c`` could be pulled on to, ``avoid`` aside and a dead end its
    occupant's goal (who needs not move): how many, and the last of them."""
    count, last = 0, -1
    x, y = c % width, c // width
    for a in range(N_ACTIONS - 1):
        u = target_y(y, a, height) * width + target_x(x, a, width)
        if u == c or blocked[u] != 0 or u == avoid:
            continue
        k = occupant[u]
        if k >= 0 and k < n and goal_y[k] * width + goal_x[k] == u \
                and _degree(u, width, height, blocked) == 1:
            continue
        count += 1
        last = u
    return count, last


@kernel
def _degree(c, width, height, blocked):
    x, y = c % width, c // width
    count = 0
    for a in range(N_ACTIONS - 1):
        u = target_y(y, a, height) * width + target_x(x, a, width)
        if u != c and blocked[u] == 0:
            count += 1
    return count


@kernel
def _swap_required(pusher, puller, v_pusher, v_puller, width, height, distances, blocked,
                   occupant, goal_x, goal_y, n):
    """Whether ``pusher`` (at ``v_pusher``) and ``puller`` must trade places: the way ahead of
    the pusher gives no room to pass, and each is nearer its goal in the other's place."""
    cells = width * height
    d = pusher * cells
    e = puller * cells
    for _ in range(cells):
        if distances[d + v_puller] >= distances[d + v_pusher]:
            break
        count, last = _way_out(v_puller, v_pusher, width, height, blocked, occupant, goal_x,
                               goal_y, n)
        if count >= 2:
            return False
        if count <= 0:
            break
        v_pusher, v_puller = v_puller, last
    return distances[e + v_pusher] < distances[e + v_puller] and (
        distances[d + v_pusher] == 0 or distances[d + v_puller] < distances[d + v_pusher])


@kernel
def _swap_possible(v_pusher, v_puller, width, height, blocked, occupant, goal_x, goal_y, n):
    """Whether pulling from ``v_puller`` away from ``v_pusher`` reaches a cell with room to
    pass."""
    origin = v_pusher
    for _ in range(width * height):
        if v_puller == origin:
            return False
        count, last = _way_out(v_puller, v_pusher, width, height, blocked, occupant, goal_x,
                               goal_y, n)
        if count >= 2:
            return True
        if count <= 0:
            return False
        v_pusher, v_puller = v_puller, last
    return False


@kernel
def _swap_partner(i, x, y, width, height, distances, occupant, decided, blocked, goal_x, goal_y,
                  n):
    """The agent ``i`` must swap with (LaCAM's ``is_swap_required_and_possible``), or -1: the
    one in the cell nearest its goal, or, to clear the way, a neighbour behind it."""
    cells = width * height
    here = y[i] * width + x[i]
    best, best_d = here, distances[i * cells + here]
    for a in range(N_ACTIONS - 1):
        c = target_y(y[i], a, height) * width + target_x(x[i], a, width)
        if c != here and blocked[c] == 0 and distances[i * cells + c] < best_d:
            best, best_d = c, distances[i * cells + c]
    j = occupant[best]
    if j >= 0 and j < n and j != i and not decided[j] \
            and _swap_required(i, j, here, best, width, height, distances, blocked, occupant,
                               goal_x, goal_y, n) \
            and _swap_possible(best, here, width, height, blocked, occupant, goal_x, goal_y, n):
        return j
    if best != here:
        for a in range(N_ACTIONS - 1):
            u = target_y(y[i], a, height) * width + target_x(x[i], a, width)
            if u == here or blocked[u] != 0:
                continue
            k = occupant[u]
            if k >= 0 and k < n and u != best \
                    and _swap_required(k, i, here, best, width, height, distances, blocked,
                                       occupant, goal_x, goal_y, n) \
                    and _swap_possible(best, here, width, height, blocked, occupant, goal_x,
                                       goal_y, n):
                return k
    return -1


@kernel
def _closes(goal, i, x, y, goal_x, goal_y, arrived, n, width, height, distances, blocked, probe,
            queue):
    """Whether agent ``i`` parked on ``goal`` would leave another agent, one that can reach its
    goal now, no way to it."""
    cells = width * height
    closes = False
    if blocked[goal] != 0:  # taken by an arrival of this step already
        return closes
    blocked[goal] = 1
    for j in range(n):
        if j == i or arrived[j] or distances[j * cells + y[j] * width + x[j]] >= FAR:
            continue
        goal_distances(goal_x[j], goal_y[j], blocked, width, height, probe, 0, queue)
        reached = probe[y[j] * width + x[j]] < FAR
        for a in range(N_ACTIONS - 1):  # it may stand on a goal taken: a way from a neighbour
            nx, ny = target_x(x[j], a, width), target_y(y[j], a, height)
            reached = reached or probe[ny * width + nx] < FAR
        if not reached:
            closes = True
            break
    blocked[goal] = 0
    return closes


@kernel
def plan(x, y, goal_x, goal_y, arrived, bodies, n, width, height, step_aside, priority, closest,
         actions, distances, occupant, reserved, decided, order, blocked, queue, stack, tried,
         probe, swapper, first, step, goal_of, learned, ranks):
    """Every agent's collision-free action for this step, the agents of higher ``priority``
    first: bodies ``0 .. n - 1`` are the agents, ``n .. bodies - 1`` walls (they stay). An agent
    gains a unit of ``priority`` at every step that finds it no nearer its goal than it has been
    (``closest``, its nearest so far), so that one held back in a corridor comes to outrank those
    in its way. An agent next to its goal whose parking there would leave another agent no way
    to its own does not take it this step, and plans after the others. Under ``step_aside``
    arrived agents are planned (and pushed) like the others, and priorities are published
    PIBT's (the module docstring), with LaCAM's swap (:func:`_push`); there the distances depend
    on the goals and walls alone, and are worked out again only for an agent whose goal is not
    the one they were worked out for (``goal_of``, a cell per agent, -1 at first): a new episode,
    or a new goal of a lifelong run (``world.tasks``), after which, as in lifelong PIBT, its
    priority starts again from 0.
    With ``learned``, each agent's order over its moves is its own (``ranks``, :func:`_push`),
    not the distance to its goal: the arbitration of ``--arbitration pibt``, the same machinery
    with the agents' preferences. Scratch: ``distances`` (n cells each), ``occupant``,
    ``reserved``, ``blocked``, ``queue``, ``probe`` (a slot per cell), ``decided``, ``order``,
    ``stack``, ``tried``, ``swapper``, ``first`` (a slot per agent)."""
    cells = width * height
    for c in range(cells):
        occupant[c] = -1
        reserved[c] = -1
        blocked[c] = 0
    for i in range(bodies):
        occupant[y[i] * width + x[i]] = i
        decided[i] = False
        actions[i] = STAY
        if i >= n or (arrived[i] and not step_aside):
            blocked[y[i] * width + x[i]] = 1
            reserved[y[i] * width + x[i]] = i
            decided[i] = True
    if step_aside:
        for i in range(n):
            goal = goal_y[i] * width + goal_x[i]
            if goal_of[i] != goal:
                goal_distances(goal_x[i], goal_y[i], blocked, width, height, distances,
                               i * cells, queue)
                goal_of[i] = goal
                if step > 0:
                    priority[i] = 0
            if x[i] == goal_x[i] and y[i] == goal_y[i]:
                priority[i] = 0
            else:
                priority[i] += cells
            order[i] = i
        _by_priority(order, n, priority)
        for a in range(n):
            i = order[a]
            if not decided[i]:
                _push(i, x, y, width, height, distances, occupant, reserved, decided, actions,
                      stack, tried, True, blocked, goal_x, goal_y, n, swapper, first, step,
                      learned, ranks)
        return
    for i in range(n):
        if not arrived[i]:
            goal_distances(goal_x[i], goal_y[i], blocked, width, height, distances, i * cells,
                           queue)
            here = distances[i * cells + y[i] * width + x[i]]
            if here < closest[i]:
                closest[i] = here
            else:  # no nearer than it has ever been: it gains on those that make way
                priority[i] += 1
    for i in range(n):  # an arrival that would close another's last way waits; the arrivals
        # of this step close ways together, so each one let through counts for the next
        if not arrived[i] and distances[i * cells + y[i] * width + x[i]] == 1:
            goal = goal_y[i] * width + goal_x[i]
            if _closes(goal, i, x, y, goal_x, goal_y, arrived, n, width, height, distances,
                       blocked, probe, queue):
                distances[i * cells + goal] = FAR + 1  # not even when pushed
            else:
                blocked[goal] = 1
    count = 0
    for i in range(n):
        if not arrived[i]:
            order[count] = i
            count += 1
    for a in range(count):  # insertion sort: waiting arrivals last, then by priority, then id
        for b in range(a, 0, -1):
            i, j = order[b], order[b - 1]
            wait_i = distances[i * cells + goal_y[i] * width + goal_x[i]] != 0
            wait_j = distances[j * cells + goal_y[j] * width + goal_x[j]] != 0
            if (not wait_i and wait_j) or (wait_i == wait_j and priority[i] > priority[j]):
                order[b], order[b - 1] = j, i
            else:
                break
    for a in range(count):
        i = order[a]
        if not decided[i]:
            _push(i, x, y, width, height, distances, occupant, reserved, decided, actions, stack,
                  tried, False, blocked, goal_x, goal_y, n, swapper, first, step, learned, ranks)


PIBT_SIGNATURE = ("void(i8[::1], i8[::1], i8[::1], i8[::1], b1[::1], i8, i8, i8, i8, b1, i8[::1], "
                  "i8[::1], i8[::1], i8[::1], i8[::1], i8[::1], b1[::1], i8[::1], i8[::1], "
                  "i8[::1], i8[::1], i8[::1], i8[::1], i8[::1], i8[::1], i8, i8[::1], b1, "
                  "i8[::1])")
""":func:`plan`'s types, as compiled ahead of time for the world process (``world.rules_ahead``):
every buffer a C-contiguous numpy array, integers ``int64``, flags ``bool``."""


@kernel
def _by_priority(order, count, priority):
    """Sort ``order[:count]`` by priority, the highest first (stable: among equals, by id)."""
    for a in range(count):
        for b in range(a, 0, -1):
            i, j = order[b], order[b - 1]
            if priority[i] > priority[j]:
                order[b], order[b - 1] = j, i
            else:
                break
