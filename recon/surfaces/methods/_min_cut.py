"""The source side of a minimum s-t cut: Boykov-Kolmogorov maximum flow, compiled with numba.

Boykov and Kolmogorov (2004, "An experimental comparison of min-cut/max-flow algorithms for
energy minimization in vision", IEEE TPAMI 26(9)) grow two search trees, one from each terminal,
along arcs with residual capacity; where they touch, the path between the terminals is
augmented, the nodes it cut off (orphans) look for a new parent in their tree or become free,
and the growth goes on. On the graphs of a Delaunay tetrahedralisation cut by sensor rays
(``visibility``, ``delaunay_balls``) the trees are reused between augmentations instead of
being searched anew level by level (Dinic), which is what makes it fast there.

The side returned is the set of nodes the source reaches in the residual graph of the maximum
flow (a search along the residual arcs once the flow is maximal): the smallest
source side of any minimum cut, the same for every maximum flow, so it does not depend on which
maximum flow the trees found: the cut scipy's Dinic maximum flow and a breadth-first search of
its residual graph give, which this replaced (tests/recon/surfaces/test_min_cut.py checks the
two agree). On the visibility graph of castalia-cross-clean (7,740 noise-free strikes along a
cross's lines, 323,786 Delaunay cells, 1.3 million arcs) it takes 0.29 of Dinic's time; on a
noisy satellite's (satellite W, 35,607 cells) 0.85 (benchmarks/bench_min_cut.py, medians of
three; docs/decisions.md).

The kernels are compiled for their one signature when this module is imported, from numba's
cache after the first time (``cache=True``: about 0.4 s to load, 0.2 s more for numba's own
import); the fit workers import it before their first job (``isolation.WORKER_PRELOAD``).
"""

from __future__ import annotations

import numpy as np
from numba import njit

# The kernels' graph: arcs grouped by tail (``first[i]:first[i + 1]`` leave node i), each with
# its ``head``, its ``residual`` capacity and its ``sister`` (the reverse arc); a node's
# ``terminal`` capacity is its residual capacity from the source (> 0) or, negated, to the sink
# (< 0). A node's ``parent`` is the arc from it to its parent in its tree, or one of these:
_NONE, _TERMINAL, _ORPHAN = -1, -2, -3     # free; a root (a terminal arc); lost its parent
_INFINITE = 1 << 60                        # above any distance and any bottleneck


def source_side(n_nodes: int, indptr: np.ndarray, indices: np.ndarray, capacity: np.ndarray,
                source: int, sink: int) -> np.ndarray:
    """The nodes on the source side of the minimal minimum ``source``-``sink`` cut.

    Parameters
    ----------
    n_nodes : int
    indptr, indices : (n_nodes + 1,), (e,) int
        The arcs in compressed sparse rows: arc ``k`` goes from the row ``i`` with
        ``indptr[i] <= k < indptr[i + 1]`` to ``indices[k]``.
    capacity : (e,) int
        The arcs' capacities, >= 0 (repeated arcs add up).
    source, sink : int

    Returns
    -------
    (n_nodes,) bool
        The nodes the source reaches in the residual graph of a maximum flow.
    """
    tails = np.repeat(np.arange(n_nodes, dtype=np.int64),
                      np.diff(np.asarray(indptr, dtype=np.int64)))
    return _source_side(int(n_nodes), tails, np.asarray(indices, dtype=np.int64),
                        np.asarray(capacity, dtype=np.int64), int(source), int(sink))


@njit(cache=True)
def _grow_and_augment(n, first, head, residual, sister, terminal):  # pragma: no cover
    """Push a maximum flow: ``residual`` and ``terminal`` are left as its residual graph."""
    parent = np.full(n, _NONE, np.int64)
    in_sink = terminal < 0
    stamp = np.zeros(n, np.int64)
    distance = np.zeros(n, np.int64)
    active = np.zeros(n, np.bool_)
    queue = np.empty(n + 1, np.int64)          # a ring of the active nodes
    q_head, q_tail = 0, 0
    orphans = np.empty(n, np.int64)            # a stack (each node an orphan once at a time)
    for i in np.flatnonzero(terminal != 0):
        parent[i] = _TERMINAL
        distance[i] = 1
        q_tail = _activate(i, active, queue, q_tail)
    time = 0
    current = -1
    while True:
        i = -1
        if current >= 0:                       # the node a path was found from: grow it again
            active[current] = False
            if parent[current] != _NONE:
                i = current
            current = -1
        if i < 0:
            i, q_head = _next_active(active, parent, queue, q_head, q_tail)
        if i < 0:
            return
        middle, q_tail = _grow(i, first, head, residual, sister, parent, in_sink, stamp,
                               distance, active, queue, q_tail)
        time += 1
        if middle < 0:
            continue
        active[i] = True
        current = i
        n_orphans = _augment(middle, head, residual, sister, terminal, parent, orphans)
        while n_orphans > 0:
            n_orphans -= 1
            o = orphans[n_orphans]
            best, d = _nearest_root(o, in_sink[o], first, head, residual, sister, parent,
                                    in_sink, stamp, distance, time)
            if best >= 0:
                parent[o], stamp[o], distance[o] = best, time, d + 1
            else:
                n_orphans, q_tail = _free(o, in_sink[o], first, head, residual, sister,
                                          parent, in_sink, active, queue, q_tail, orphans,
                                          n_orphans)


@njit(cache=True)
def _activate(j, active, queue, q_tail):  # pragma: no cover
    """Put node ``j`` at the end of the active ring unless it is in it; returns the tail."""
    if not active[j]:
        active[j] = True
        queue[q_tail] = j
        q_tail = (q_tail + 1) % len(queue)
    return q_tail


@njit(cache=True)
def _next_active(active, parent, queue, q_head, q_tail):  # pragma: no cover
    """The first active node still in a tree (-1: none left), and the ring's new head."""
    while q_head != q_tail:
        j = queue[q_head]
        q_head = (q_head + 1) % len(queue)
        active[j] = False
        if parent[j] != _NONE:
            return j, q_head
    return -1, q_head


@njit(cache=True)
def _grow(i, first, head, residual, sister, parent, in_sink, stamp, distance, active, queue,
          q_tail):  # pragma: no cover
    """Grow node ``i``'s tree by its free neighbours along open arcs; the first open arc into
    the other tree, oriented source tree to sink tree, is returned (-1: none), with the ring's
    tail."""
    for a in range(first[i], first[i + 1]):
        if residual[sister[a] if in_sink[i] else a] <= 0:
            continue
        j = head[a]
        if parent[j] == _NONE:
            in_sink[j] = in_sink[i]
            parent[j], stamp[j], distance[j] = sister[a], stamp[i], distance[i] + 1
            q_tail = _activate(j, active, queue, q_tail)
        elif in_sink[j] != in_sink[i]:
            return (sister[a] if in_sink[i] else a), q_tail
        elif stamp[j] <= stamp[i] and distance[j] > distance[i]:   # a shorter way to the root
            parent[j], stamp[j], distance[j] = sister[a], stamp[i], distance[i] + 1
    return -1, q_tail


@njit(cache=True)
def _augment(middle, head, residual, sister, terminal, parent, orphans):  # pragma: no cover
    """Push the bottleneck along the path through arc ``middle`` (source tree to sink tree);
    the nodes whose parent arc saturates go on the ``orphans`` stack. Returns its size."""
    source_end, sink_end = head[sister[middle]], head[middle]
    bottleneck = min(residual[middle],
                     _bottleneck(source_end, head, residual, sister, terminal, parent, False),
                     _bottleneck(sink_end, head, residual, sister, terminal, parent, True))
    residual[sister[middle]] += bottleneck
    residual[middle] -= bottleneck
    n_orphans = _push(source_end, bottleneck, head, residual, sister, terminal, parent, False,
                      orphans, 0)
    return _push(sink_end, bottleneck, head, residual, sister, terminal, parent, True, orphans,
                 n_orphans)


@njit(cache=True)
def _bottleneck(i, head, residual, sister, terminal, parent, sink_tree):  # pragma: no cover
    """The least residual capacity from node ``i`` to its tree's root and terminal."""
    least = _INFINITE
    while parent[i] != _TERMINAL:
        a = parent[i]
        least = min(least, residual[a] if sink_tree else residual[sister[a]])
        i = head[a]
    return min(least, -terminal[i] if sink_tree else terminal[i])


@njit(cache=True)
def _push(i, amount, head, residual, sister, terminal, parent, sink_tree, orphans,
          n_orphans):  # pragma: no cover
    """Push ``amount`` between node ``i`` and its tree's terminal; the nodes whose parent arc
    (or terminal arc) saturates become orphans. Returns the orphans' stack size."""
    while parent[i] != _TERMINAL:
        a = parent[i]
        down, up = (sister[a], a) if sink_tree else (a, sister[a])   # up: along the flow
        residual[down] += amount
        residual[up] -= amount
        if residual[up] == 0:
            parent[i] = _ORPHAN
            orphans[n_orphans] = i
            n_orphans += 1
        i = head[a]
    terminal[i] += amount if sink_tree else -amount
    if terminal[i] == 0:
        parent[i] = _ORPHAN
        orphans[n_orphans] = i
        n_orphans += 1
    return n_orphans


@njit(cache=True)
def _nearest_root(i, sink_tree, first, head, residual, sister, parent, in_sink, stamp, distance,
                  time):  # pragma: no cover
    """The open arc from orphan ``i`` to the neighbour in its tree nearest a root by a path
    with no orphan on it (-1: none), and that neighbour's distance; the nodes on the paths
    checked are stamped with ``time`` and their distance."""
    best, best_distance = -1, _INFINITE
    for a0 in range(first[i], first[i + 1]):
        j = head[a0]
        if residual[a0 if sink_tree else sister[a0]] <= 0 or in_sink[j] != sink_tree or \
                parent[j] == _NONE:
            continue
        d = _root_distance(j, head, parent, stamp, distance, time)
        if d >= _INFINITE:
            continue
        if d < best_distance:
            best, best_distance = a0, d
        k = j
        while stamp[k] != time:
            stamp[k], distance[k] = time, d
            d -= 1
            k = head[parent[k]]
    return best, best_distance


@njit(cache=True)
def _root_distance(j, head, parent, stamp, distance, time):  # pragma: no cover
    """Steps from node ``j`` up to a root (or to a node stamped ``time``, plus its distance);
    ``_INFINITE`` when the path meets an orphan."""
    d = 0
    k = j
    while True:
        if stamp[k] == time:
            return d + distance[k]
        a = parent[k]
        d += 1
        if a == _TERMINAL:
            stamp[k], distance[k] = time, 1
            return d
        if a == _ORPHAN:
            return _INFINITE
        k = head[a]


@njit(cache=True)
def _free(i, sink_tree, first, head, residual, sister, parent, in_sink, active, queue, q_tail,
          orphans, n_orphans):  # pragma: no cover
    """Orphan ``i`` found no parent: it leaves its tree; its children become orphans and its
    tree's neighbours with an open arc to it active. Returns the orphans' stack size and the
    ring's tail."""
    parent[i] = _NONE
    for a0 in range(first[i], first[i + 1]):
        j = head[a0]
        if in_sink[j] != sink_tree or parent[j] == _NONE:
            continue
        if residual[a0 if sink_tree else sister[a0]] > 0:
            q_tail = _activate(j, active, queue, q_tail)
        a = parent[j]
        if a != _TERMINAL and a != _ORPHAN and head[a] == i:
            parent[j] = _ORPHAN
            orphans[n_orphans] = j
            n_orphans += 1
    return n_orphans, q_tail


@njit(cache=True)
def _reached(n, first, head, residual, terminal, s, t):  # pragma: no cover
    """The nodes the source reaches along residual arcs (its own, ``terminal > 0``, first)."""
    side = terminal > 0
    stack = np.flatnonzero(side)
    stack = np.concatenate((stack, np.empty(n - len(stack), np.int64)))
    top = int(side.sum())
    while top > 0:
        top -= 1
        i = stack[top]
        for a in range(first[i], first[i + 1]):
            j = head[a]
            if residual[a] > 0 and not side[j]:
                side[j] = True
                stack[top] = j
                top += 1
    side[s] = True
    side[t] = False
    return side


@njit(cache=True)
def _terminal_capacities(n, tails, heads, capacity, s, t):  # pragma: no cover
    """Each node's terminal capacity (from the source minus to the sink: a path s -> i -> t
    carries the smaller at once) and which arcs join two other nodes."""
    terminal = np.zeros(n, np.int64)
    inner = np.zeros(len(tails), np.bool_)
    for k in range(len(tails)):
        u, v = tails[k], heads[k]
        if u == s and v != t and v != s:
            terminal[v] += capacity[k]
        elif v == t and u != s and u != t:
            terminal[u] -= capacity[k]
        else:
            inner[k] = u != s and u != t and v != s and v != t and u != v
    return terminal, inner


@njit("b1[:](i8, i8[:], i8[:], i8[:], i8, i8)", cache=True)
def _source_side(n, tails, heads, capacity, s, t):  # pragma: no cover - compiled
    """``source_side`` on the arcs ``tails[k] -> heads[k]`` of ``capacity[k]``."""
    terminal, inner = _terminal_capacities(n, tails, heads, capacity, s, t)
    # arcs 2k (u -> v, its capacity) and 2k + 1 (v -> u, none), then grouped by tail
    u, v, c = tails[inner], heads[inner], capacity[inner]
    m = 2 * len(u)
    tail, head = np.empty(m, np.int64), np.empty(m, np.int64)
    residual = np.zeros(m, np.int64)
    tail[0::2], tail[1::2], head[0::2], head[1::2], residual[0::2] = u, v, v, u, c
    order = np.argsort(tail, kind="mergesort")
    rank = np.empty(m, np.int64)
    rank[order] = np.arange(m)
    first = np.zeros(n + 1, np.int64)
    first[1:] = np.cumsum(np.bincount(tail, minlength=n))
    head, residual = head[order], residual[order]
    sister = rank[order ^ 1]
    _grow_and_augment(n, first, head, residual, sister, terminal)
    return _reached(n, first, head, residual, terminal, s, t)
