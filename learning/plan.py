"""Whom an agent waits for, asks, answers, knows to stay and streams at an observation: kernel
functions over its neighbours as rows ``(id, x, y)``.

The rules are ``protocol.ranks``' (:func:`~nnql_swarm.protocol.ranks.awaits_answer`,
``waits_for``); what they mean for the negotiation, ``agent.negotiation``'s docstring. Every
function here reads the observation's neighbours ``nb`` (its first ``k`` rows, in id order) and
the ids of its parked ones (``parked``, the first ``p``), and writes the indices into ``nb`` of
those it finds into ``out``, in the order the rule gives; it returns how many. Scratch buffers
(``xs``, ``ys``, ``ranks``...) have room for every neighbour and the agent itself.
:func:`negotiation_plan` is all of them at once; :func:`agent_plan` is that for the agent, from
its observation's packed neighbours (:func:`unpack_seen_into`), compiled ahead of time with the
agent's decision (``learning.ahead``), so that an agent plans its tick in one call;
:func:`world_plans` is every agent's plan at once as the world reads it, from the cells of all.
"""

from nnql_swarm.protocol.actions import sees
from nnql_swarm.protocol.jit import kernel
from nnql_swarm.protocol.messages import NEIGHBOUR_ITEMS
from nnql_swarm.protocol.ranks import awaits_answer, priority_rank, waits_for

P_AWAITED, P_ASKS, P_STAYING, P_ANSWERED, P_STREAMED, PLAN_PARTS = 0, 1, 2, 3, 4, 5
"""The rows of :func:`negotiation_plan`'s ``out`` and ``counts``: whose intents the agent waits
for; whom of them it asks; the parked neighbours it knows stay; whom it answers through their
standing queries; the agents it streams with."""

P_FITS = PLAN_PARTS
"""The last of ``counts``: 1 if the observation's neighbours are the run's agents on its grid
(:func:`fits_run`), else 0 and no plan."""

S_XS, S_YS, S_RANKS, S_PARKED, S_CELL, S_WAITERS, S_WAITER_RANKS, S_MEMBERS, S_ORDER, \
    S_COVERED, S_ASKS, S_SEEN, SCRATCH = range(13)
"""The rows of the scratch buffer, each with room for every neighbour and the agent: cells,
ranks and whether parked of the agents a plan reads; each one's row in ``nb``; the waiters and
their ranks; an ask's members, their order and which are covered; the asks; by agent id, which
are among the neighbours (:func:`fits_run`: all 0 between calls)."""


@kernel
def near(nb, i, x, y, distance):
    """Whether neighbour row ``i`` is at most ``distance`` king's moves from ``(x, y)``."""
    return abs(nb[i][1] - x) <= distance and abs(nb[i][2] - y) <= distance


@kernel
def is_parked(j, parked, p):
    """Whether ``j`` is among the first ``p`` ids of ``parked``."""
    for q in range(p):
        if parked[q] == j:
            return True
    return False


@kernel
def fits_run(nb, k, parked, p, agent, n, width, height, seen):
    """Whether every neighbour is one of the run's ``n`` agents on its grid, none twice and none
    the agent itself (``agent``), and every parked id one of its agents: compiled code reads its
    buffers unchecked, so a forged observation must not reach it. Ids and cells are never
    negative (the wire packs them unsigned). ``seen``: ``n`` zeros, left so."""
    for i in range(k):
        if nb[i][0] >= n or nb[i][1] >= width or nb[i][2] >= height:
            return False
    for q in range(p):
        if parked[q] >= n:
            return False
    fits = True
    listed = 0
    for i in range(k):
        j = nb[i][0]
        if j == agent or seen[j] != 0:
            fits = False
            break
        seen[j] = 1
        listed += 1
    for i in range(listed):
        seen[nb[i][0]] = 0
    return fits


@kernel
def awaited_into(nb, k, parked, p, x, y, rank, tick, n, radius, meet, arrived, out):
    """The neighbours whose intents an agent of ``rank`` at ``(x, y)`` waits for, in id order:
    higher-ranked, within ``radius``, whose answer it awaits (``awaits_answer``; ``arrived``: it
    has arrived and may not step aside). None under ``meet`` once arrived."""
    if meet and arrived:
        return 0
    count = 0
    for i in range(k):
        if near(nb, i, x, y, radius):
            j = nb[i][0]
            other = priority_rank(j, tick, n)
            if other < rank and awaits_answer(rank, other, x, y, nb[i][1], nb[i][2], radius,
                                              meet, arrived, is_parked(j, parked, p)):
                out[count] = i
                count += 1
    return count


@kernel
def staying_into(nb, k, parked, p, x, y, rank, tick, n, radius, out):
    """Under ``meet``, the parked neighbours whose intents (STAY) the agent knows without
    waiting: those ``waits_for`` names, in id order."""
    count = 0
    for i in range(k):
        j = nb[i][0]
        if near(nb, i, x, y, radius) and is_parked(j, parked, p) and waits_for(
                True, rank, priority_rank(j, tick, n), x, y, nb[i][1], nb[i][2], radius, True):
            out[count] = i
            count += 1
    return count


@kernel
def asks_into(members, m, xs, ys, ranks, radius, meet, order, covered, out):
    """The fewest of ``members`` (indices into ``xs``, ``ys``, ``ranks``: cells and ranks) to
    ask, lowest-ranked first, whose answers, with what each relays, bring every member's intent:
    each asked member covers those it waits for itself (``waits_for``). Ranks are distinct."""
    for s in range(m):
        order[s] = members[s]
        covered[s] = 0
    for s in range(1, m):  # by rank, the lowest first (the largest number)
        v = order[s]
        t = s
        while t > 0 and ranks[order[t - 1]] < ranks[v]:
            order[t] = order[t - 1]
            t -= 1
        order[t] = v
    count = 0
    for s in range(m):
        q = order[s]
        if covered[s] != 0:
            continue
        out[count] = q
        count += 1
        covered[s] = 1
        for t in range(m):
            u = order[t]
            if waits_for(True, ranks[q], ranks[u], xs[q], ys[q], xs[u], ys[u], radius, meet):
                covered[t] = 1
    return count


@kernel
def answered_into(nb, k, parked, p, x, y, rank, tick, n, radius, meet, plans_known, scratch,
                  out):
    """The neighbours that the agent answers through their standing queries, the next in rank
    first: those that wait for it (lower-ranked, within ``radius``, awaiting its answer) whose
    plan (:func:`asks_into`) asks it, where the agent can tell (``plans_known``: it sees every
    agent its waiters wait for); else every one that waits for it."""
    waiters, waiter_ranks = scratch[S_WAITERS], scratch[S_WAITER_RANKS]
    w = 0
    for i in range(k):
        if near(nb, i, x, y, radius):
            j = nb[i][0]
            r = priority_rank(j, tick, n)
            if r > rank and awaits_answer(r, rank, nb[i][1], nb[i][2], x, y, radius, meet,
                                          is_parked(j, parked, p), False):
                t = w  # kept in rank order, the next below the agent first
                while t > 0 and waiter_ranks[t - 1] > r:
                    waiters[t], waiter_ranks[t] = waiters[t - 1], waiter_ranks[t - 1]
                    t -= 1
                waiters[t], waiter_ranks[t] = i, r
                w += 1
    if w == 0 or not plans_known:
        for s in range(w):
            out[s] = waiters[s]
        return w
    xs, ys, ranks = scratch[S_XS], scratch[S_YS], scratch[S_RANKS]
    parks, cell = scratch[S_PARKED], scratch[S_CELL]
    c = 0  # the waiters and those they wait for: within twice the radius, then the agent
    for i in range(k):
        if near(nb, i, x, y, 2 * radius):
            xs[c], ys[c] = nb[i][1], nb[i][2]
            ranks[c] = priority_rank(nb[i][0], tick, n)
            parks[c] = 1 if is_parked(nb[i][0], parked, p) else 0
            cell[c] = i
            c += 1
    xs[c], ys[c], ranks[c], parks[c], cell[c] = x, y, rank, 0, -1
    me = c
    c += 1
    members, asks = scratch[S_MEMBERS], scratch[S_ASKS]
    answered = 0
    for s in range(w):
        at = 0
        while cell[at] != waiters[s]:
            at += 1
        m = 0
        for t in range(c):
            if ranks[t] < ranks[at] and awaits_answer(ranks[at], ranks[t], xs[at], ys[at], xs[t],
                                                      ys[t], radius, meet, False, parks[t] != 0):
                members[m] = t
                m += 1
        a = asks_into(members, m, xs, ys, ranks, radius, meet, scratch[S_ORDER],
                      scratch[S_COVERED], asks)
        for t in range(a):
            if asks[t] == me:
                out[answered] = waiters[s]
                answered += 1
    return answered


@kernel
def streamed_into(nb, k, x, y, distance, out):
    """The neighbours within ``distance``, in id order."""
    count = 0
    for i in range(k):
        if near(nb, i, x, y, distance):
            out[count] = i
            count += 1
    return count


@kernel
def negotiation_plan(nb, k, parked, p, agent, x, y, rank, tick, n, width, height, radius, meet,
                     arrived, negotiating, stays, plans_known, stream_reach, whole, scratch, out,
                     counts):
    """An agent's whole plan at an observation, each part into its row of ``out`` (``P_*``) and
    its count into ``counts``: whom it waits for (:func:`awaited_into`) and asks
    (:func:`asks_into`), whom it knows to stay where ``stays`` (:func:`staying_into`), whom it
    answers (:func:`answered_into`), all only where it ``negotiates``; and whom it streams
    with, within ``stream_reach`` (:func:`streamed_into`); every part as ids. Unless ``whole``,
    only whom it waits for and knows to stay (what the world reads). Nothing where the
    neighbours are not the run's agents on its grid, each once and other than ``agent``
    (``counts[P_FITS]`` 0: :func:`fits_run`)."""
    for part in range(PLAN_PARTS):
        counts[part] = 0
    counts[P_FITS] = 1 if fits_run(nb, k, parked, p, agent, n, width, height,
                                   scratch[S_SEEN]) else 0
    if counts[P_FITS] == 0:
        return
    if negotiating:
        a = awaited_into(nb, k, parked, p, x, y, rank, tick, n, radius, meet, arrived,
                         out[P_AWAITED])
        counts[P_AWAITED] = a
        if a > 0 and whole:
            xs, ys, ranks = scratch[S_XS], scratch[S_YS], scratch[S_RANKS]
            for i in range(k):
                xs[i], ys[i] = nb[i][1], nb[i][2]
                ranks[i] = priority_rank(nb[i][0], tick, n)
            counts[P_ASKS] = asks_into(out[P_AWAITED], a, xs, ys, ranks, radius, meet,
                                       scratch[S_ORDER], scratch[S_COVERED], out[P_ASKS])
        if stays:
            counts[P_STAYING] = staying_into(nb, k, parked, p, x, y, rank, tick, n, radius,
                                             out[P_STAYING])
        if whole and not (meet and arrived):
            counts[P_ANSWERED] = answered_into(nb, k, parked, p, x, y, rank, tick, n, radius,
                                               meet, plans_known, scratch, out[P_ANSWERED])
    if whole:
        counts[P_STREAMED] = streamed_into(nb, k, x, y, stream_reach, out[P_STREAMED])
    for part in range(PLAN_PARTS):  # the agents, by id
        row = out[part]
        for s in range(counts[part]):
            row[s] = nb[row[s]][0]


@kernel
def unpack_seen_into(seen, k, p, nb, parked):
    """An observation's neighbours and parked ids as the kernels read them: ``seen`` is its two
    packings one after the other, as their integers (``protocol.messages.pack_neighbours``:
    ``k`` neighbours of :data:`~nnql_swarm.protocol.messages.NEIGHBOUR_ITEMS` each, ``(id, x,
    y)``; then ``p`` ids), into the first ``k`` rows of ``nb`` and the first ``p`` of
    ``parked``."""
    for i in range(k):
        for item in range(NEIGHBOUR_ITEMS):
            nb[i][item] = seen[NEIGHBOUR_ITEMS * i + item]
    for q in range(p):
        parked[q] = seen[NEIGHBOUR_ITEMS * k + q]


UNPACK_SIGNATURE = "void(u2[::1], i8, i8, i8[:, ::1], i8[::1])"
""":func:`unpack_seen_into`'s types, as compiled ahead of time (``learning.ahead``)."""


@kernel
def agent_plan(seen, k, p, agent, x, y, rank, tick, n, width, height, radius, meet, arrived,
               negotiating, stays, plans_known, stream_reach, nb, parked, scratch, out, counts,
               flat):
    """An agent's whole plan at an observation (:func:`negotiation_plan`), from its packed
    neighbours and parked ids (``seen``, ``k``, ``p``: :func:`unpack_seen_into`, into ``nb`` and
    ``parked``): each part into its row of ``out`` and its count into ``counts``, and every part
    one after the other into ``flat``, in ``P_*`` order; how many ids that is."""
    unpack_seen_into(seen, k, p, nb, parked)
    negotiation_plan(nb, k, parked, p, agent, x, y, rank, tick, n, width, height, radius, meet,
                     arrived, negotiating, stays, plans_known, stream_reach, True, scratch, out,
                     counts)
    total = 0
    for part in range(PLAN_PARTS):
        row = out[part]
        for s in range(counts[part]):
            flat[total] = row[s]
            total += 1
    return total


PLAN_SIGNATURE = ("i8(u2[::1], i8, i8, i8, i8, i8, i8, i8, i8, i8, i8, i8, b1, b1, b1, b1, b1, "
                  "i8, i8[:, ::1], i8[::1], i8[:, ::1], i8[:, ::1], i8[::1], i8[::1])")
""":func:`agent_plan`'s types, as compiled ahead of time."""


@kernel
def world_plans(xs, ys, arrived, n, sees_all, parks, tick, width, height, radius, meet,
                parks_still, negotiating, nbs, ks, parkeds, ps, scratch, out, counts, awaited,
                n_awaited, staying, n_staying):
    """What the world reads of every agent's plan at a tick (:func:`negotiation_plan`, not
    whole), from the ``n`` agents' cells ``(xs, ys)`` and whether each has ``arrived``, as the
    tick's observations show them: each agent's neighbours are the others it sees (every other
    where ``sees_all``: the grid fits in the view) in id order, into ``nbs[i]``'s first
    ``ks[i]`` rows ``(id, x, y)``; its parked ones those of them that arrived, where arrived
    agents park (``parks``), into ``parkeds[i]``'s first ``ps[i]``; whom it waits for into
    ``awaited[i]``'s first ``n_awaited[i]``, and whom it knows to stay into ``staying[i]``'s
    first ``n_staying[i]``, as ids."""
    for i in range(n):
        nb = nbs[i]
        parked = parkeds[i]
        k = 0
        p = 0
        for j in range(n):
            if j == i or not (sees_all or sees(xs[i], ys[i], xs[j], ys[j])):
                continue
            nb[k][0] = j
            nb[k][1] = xs[j]
            nb[k][2] = ys[j]
            k += 1
            if parks and arrived[j] != 0:
                parked[p] = j
                p += 1
        ks[i] = k
        ps[i] = p
        negotiation_plan(nb, k, parked, p, i, xs[i], ys[i], priority_rank(i, tick, n), tick, n,
                         width, height, radius, meet, arrived[i] != 0 and parks_still,
                         negotiating, meet and p > 0, False, 0, False, scratch, out, counts)
        n_awaited[i] = counts[P_AWAITED]
        for s in range(counts[P_AWAITED]):
            awaited[i][s] = out[P_AWAITED][s]
        n_staying[i] = counts[P_STAYING]
        for s in range(counts[P_STAYING]):
            staying[i][s] = out[P_STAYING][s]


WORLD_PLANS_SIGNATURE = (
    "void(i8[::1], i8[::1], i8[::1], i8, b1, b1, i8, i8, i8, i8, b1, b1, b1, i8[:, :, ::1], "
    "i8[::1], i8[:, ::1], i8[::1], i8[:, ::1], i8[:, ::1], i8[::1], i8[:, ::1], i8[::1], "
    "i8[:, ::1], i8[::1])")
""":func:`world_plans`' types, as compiled ahead of time (``learning.ahead``)."""
