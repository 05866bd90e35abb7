"""The oracle: every goal known, moves planned for all agents at once, collision-free (PIBT).

Priority Inheritance with Backtracking (Okumura et al., 2022), one step at a time, on the world's
rules: agents in a fixed priority order for the episode (the farthest from its goal at the start
first, then by id; as PIBT's priorities when all grow alike) each take the free neighbouring cell
nearest their goal (breadth-first distances around parked agents); an agent
that wants a cell someone still occupies makes that one move first (it inherits the priority) and
tries its next cell if it cannot. No two agents are planned into one cell and no two swap, so the
world's arbitration never finds a collision; arrived agents are parked obstacles, as in the swarm.
It learns nothing: it is the lower bound the learners are read against.
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
def plan(x, y, goal_x, goal_y, arrived, n, width, height, priority, actions, distances,
         occupant, reserved, decided, order, blocked, queue, stack, tried):
    """Every agent's collision-free action for this step, the agents of higher ``priority``
    first. Scratch: ``distances`` (n cells each), ``occupant``, ``reserved``, ``blocked``,
    ``queue`` (a slot per cell), ``decided``, ``order``, ``stack``, ``tried`` (a slot per agent)."""
    cells = width * height
    for c in range(cells):
        occupant[c] = -1
        reserved[c] = -1
        blocked[c] = 0
    for i in range(n):
        occupant[y[i] * width + x[i]] = i
        decided[i] = False
        actions[i] = STAY
        if arrived[i]:
            blocked[y[i] * width + x[i]] = 1
            reserved[y[i] * width + x[i]] = i
            decided[i] = True
    for i in range(n):
        if not arrived[i]:
            goal_distances(goal_x[i], goal_y[i], blocked, width, height, distances, i * cells,
                           queue)
    count = 0
    for i in range(n):
        if not arrived[i]:
            order[count] = i
            count += 1
    for a in range(count):  # insertion sort by priority, then by id
        for b in range(a, 0, -1):
            i, j = order[b], order[b - 1]
            if priority[i] > priority[j]:
                order[b], order[b - 1] = j, i
            else:
                break
    for a in range(count):
        i = order[a]
        if not decided[i]:
            _push(i, x, y, width, height, distances, occupant, reserved, decided, actions, stack,
                  tried)
