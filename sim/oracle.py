"""The oracle: a reference planner (PIBT) that knows every goal and plans all agents' moves at
once, collision-free.

Priority Inheritance with Backtracking (Okumura et al., 2022), one step at a time, on the world's
rules: agents in priority order (at the start, the longest shortest path to its goal first, then
by id; an agent gains a unit of priority at each step that finds it no nearer its goal than it
has ever been, as PIBT's priorities grow while an agent is not home) each take the free
neighbouring cell nearest their goal (breadth-first distances on the grid's free cells, around the
walls and the parked agents); an agent that wants a cell someone still occupies makes that one
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
  it, so whoever has waited longest goes first.

It learns nothing. It is a reference planner, not a lower bound: PIBT's paths are not optimal.
The lower bound is ``shortest_sum``, each agent's shortest path alone.
"""

from nnql_swarm.protocol.actions import N_ACTIONS, STAY, target_x, target_y
from nnql_swarm.protocol.jit import kernel

FAR = 1 << 30
"""The distance of a cell its agent cannot reach."""


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
          tried):
    """PIBT from agent ``root``, without recursion: ``stack`` holds the chain of agents pushed so
    far (each pushed by the one below it), ``tried`` each one's candidate moves tried (bits). An
    agent takes the untried free cell nearest its goal; if someone undecided stands there, that
    one is pushed next; if a pushed agent finds nothing, it stays and the one below tries its next
    cell; the first agent that finds a free cell settles the whole chain."""
    cells = width * height
    decided[root] = True
    stack[0] = root
    tried[0] = 0
    top = 0
    while top >= 0:
        i = stack[top]
        parent = stack[top - 1] if top > 0 else -1
        here = y[i] * width + x[i]
        pushed = False
        settled = False
        while True:
            best_a, best_d = -1, FAR + 1
            for a in range(N_ACTIONS):
                if (tried[top] >> a) & 1:
                    continue
                c = target_y(y[i], a, height) * width + target_x(x[i], a, width)
                if a != STAY and c == here:
                    continue
                if distances[i * cells + c] < best_d:
                    best_a, best_d = a, distances[i * cells + c]
            if best_a < 0:  # no cell left: it stays, and the agent below tries its next one
                reserved[here] = i
                actions[i] = STAY
                break
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
            return
        else:
            top -= 1


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
         probe):
    """Every agent's collision-free action for this step, the agents of higher ``priority``
    first: bodies ``0 .. n - 1`` are the agents, ``n .. bodies - 1`` walls (they stay). An agent
    gains a unit of ``priority`` at every step that finds it no nearer its goal than it has been
    (``closest``, its nearest so far), so that one held back in a corridor comes to outrank those
    in its way. An agent next to its goal whose parking there would leave another agent no way
    to its own does not take it this step, and plans after the others. Under ``step_aside``
    arrived agents are planned (and pushed) like the others, and priorities are published
    PIBT's (the module docstring). Scratch: ``distances``
    (n cells each), ``occupant``, ``reserved``, ``blocked``, ``queue``, ``probe`` (a slot per
    cell), ``decided``, ``order``, ``stack``, ``tried`` (a slot per agent)."""
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
            goal_distances(goal_x[i], goal_y[i], blocked, width, height, distances, i * cells,
                           queue)
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
                      stack, tried)
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
                  tried)


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
