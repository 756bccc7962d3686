"""The source side of a minimum s-t cut: Boykov-Kolmogorov maximum flow, compiled with numba.

Boykov and Kolmogorov (2004, "An experimental comparison of min-cut/max-flow algorithms for
energy minimization in vision", IEEE TPAMI 26(9)) grow two search trees, one from each terminal,
along arcs with residual capacity; where they touch, the path between the terminals is
augmented, the nodes it cut off (orphans) look for a new parent in their tree or become free,
and the growth goes on. On the graphs of a Delaunay tetrahedralisation cut by sensor rays
(``visibility``, ``delaunay_balls``) the trees are reused between augmentations instead of
being searched anew level by level (Dinic), which is what makes it fast there.

The side returned is the set of nodes the source reaches in the residual graph of the maximum
flow (a breadth-first search of the residual arcs once the flow is maximal): the smallest
source side of any minimum cut, the same for every maximum flow, so it does not depend on which
maximum flow the trees found: the cut scipy's Dinic maximum flow and a breadth-first search of
its residual graph give, which this replaced (tests/recon/surfaces/test_min_cut.py checks the
two agree). On the visibility graph of castalia-cross-clean (7,740 noise-free strikes along a
cross's lines, 323,786 Delaunay cells, 1.3 million arcs) Dinic took 12.3 s and this 2.9 s; on a
noisy satellite's (satellite W, 17,495 cells on the source side) 0.14 s and 0.10 s
(benchmarks/bench_min_cut.py, docs/decisions.md).

The kernels are compiled for their one signature when this module is imported, from numba's
cache after the first time (``cache=True``: about 0.4 s to load, 0.2 s more for numba's own
import); the fit workers import it before their first job (``isolation.WORKER_PRELOAD``).
"""

from __future__ import annotations

import numpy as np
from numba import njit

_NONE, _TERMINAL, _ORPHAN = -1, -2, -3
_INFINITE_DISTANCE = 1 << 60


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
    parent = np.full(n, _NONE, np.int64)
    in_sink = np.zeros(n, np.bool_)
    stamp = np.zeros(n, np.int64)
    distance = np.zeros(n, np.int64)
    active = np.zeros(n, np.bool_)
    queue = np.empty(n + 1, np.int64)          # a ring of the active nodes
    q_head, q_tail = 0, 0
    orphans = np.empty(n, np.int64)            # a stack (each node an orphan once at a time)
    n_orphans = 0
    for i in range(n):
        if terminal[i] != 0:
            in_sink[i] = terminal[i] < 0
            parent[i] = _TERMINAL
            distance[i] = 1
            active[i] = True
            queue[q_tail] = i
            q_tail = (q_tail + 1) % (n + 1)
    time = 0
    current = -1
    while True:
        i = -1
        if current >= 0:
            active[current] = False
            if parent[current] != _NONE:
                i = current
            current = -1
        while i < 0 and q_head != q_tail:
            j = queue[q_head]
            q_head = (q_head + 1) % (n + 1)
            active[j] = False
            if parent[j] != _NONE:
                i = j
        if i < 0:
            break
        # grow the tree of i by its free neighbours; an arc into the other tree is a path
        middle = -1
        for a in range(first[i], first[i + 1]):
            j = head[a]
            if in_sink[i]:
                if residual[sister[a]] <= 0:
                    continue
            elif residual[a] <= 0:
                continue
            if parent[j] == _NONE:
                in_sink[j] = in_sink[i]
                parent[j] = sister[a]
                stamp[j] = stamp[i]
                distance[j] = distance[i] + 1
                if not active[j]:
                    active[j] = True
                    queue[q_tail] = j
                    q_tail = (q_tail + 1) % (n + 1)
            elif in_sink[j] != in_sink[i]:
                middle = sister[a] if in_sink[i] else a
                break
            elif stamp[j] <= stamp[i] and distance[j] > distance[i]:
                parent[j] = sister[a]
                stamp[j] = stamp[i]
                distance[j] = distance[i] + 1
        time += 1
        if middle < 0:
            continue
        active[i] = True                       # grown from again next (``current``)
        current = i
        n_orphans = _augment(middle, head, residual, sister, terminal, parent, orphans,
                             n_orphans)
        while n_orphans > 0:
            n_orphans -= 1
            o = orphans[n_orphans]
            n_orphans, q_tail = _adopt(o, in_sink[o], first, head, residual, sister, parent,
                                       in_sink, stamp, distance, time, active, queue, q_tail,
                                       orphans, n_orphans)


@njit(cache=True)
def _augment(middle, head, residual, sister, terminal, parent, orphans,
             n_orphans):  # pragma: no cover
    # the bottleneck: the source tree's path, the middle arc, the sink tree's path
    bottleneck = residual[middle]
    i = head[sister[middle]]
    while parent[i] != _TERMINAL:
        a = parent[i]
        bottleneck = min(bottleneck, residual[sister[a]])
        i = head[a]
    bottleneck = min(bottleneck, terminal[i])
    i = head[middle]
    while parent[i] != _TERMINAL:
        a = parent[i]
        bottleneck = min(bottleneck, residual[a])
        i = head[a]
    bottleneck = min(bottleneck, -terminal[i])
    # push it; the nodes whose parent arc saturates become orphans
    residual[sister[middle]] += bottleneck
    residual[middle] -= bottleneck
    i = head[sister[middle]]
    while parent[i] != _TERMINAL:
        a = parent[i]
        residual[a] += bottleneck
        residual[sister[a]] -= bottleneck
        if residual[sister[a]] == 0:
            parent[i] = _ORPHAN
            orphans[n_orphans] = i
            n_orphans += 1
        i = head[a]
    terminal[i] -= bottleneck
    if terminal[i] == 0:
        parent[i] = _ORPHAN
        orphans[n_orphans] = i
        n_orphans += 1
    i = head[middle]
    while parent[i] != _TERMINAL:
        a = parent[i]
        residual[sister[a]] += bottleneck
        residual[a] -= bottleneck
        if residual[a] == 0:
            parent[i] = _ORPHAN
            orphans[n_orphans] = i
            n_orphans += 1
        i = head[a]
    terminal[i] += bottleneck
    if terminal[i] == 0:
        parent[i] = _ORPHAN
        orphans[n_orphans] = i
        n_orphans += 1
    return n_orphans


@njit(cache=True)
def _adopt(i, sink_tree, first, head, residual, sister, parent, in_sink, stamp, distance,
           time, active, queue, q_tail, orphans, n_orphans):  # pragma: no cover
    n = len(parent)
    best, best_distance = -1, _INFINITE_DISTANCE
    for a0 in range(first[i], first[i + 1]):
        open_ = residual[a0] > 0 if sink_tree else residual[sister[a0]] > 0
        j = head[a0]
        if not open_ or in_sink[j] != sink_tree or parent[j] == _NONE:
            continue
        # does j's path lead to the terminal (not through an orphan)? how far?
        d = 0
        k = j
        while True:
            if stamp[k] == time:
                d += distance[k]
                break
            a = parent[k]
            d += 1
            if a == _TERMINAL:
                stamp[k] = time
                distance[k] = 1
                break
            if a == _ORPHAN:
                d = _INFINITE_DISTANCE
                break
            k = head[a]
        if d < _INFINITE_DISTANCE:
            if d < best_distance:
                best, best_distance = a0, d
            k = j
            while stamp[k] != time:
                stamp[k] = time
                distance[k] = d
                d -= 1
                k = head[parent[k]]
    if best >= 0:
        parent[i] = best
        stamp[i] = time
        distance[i] = best_distance + 1
        return n_orphans, q_tail
    parent[i] = _NONE
    for a0 in range(first[i], first[i + 1]):
        j = head[a0]
        if in_sink[j] != sink_tree or parent[j] == _NONE:
            continue
        open_ = residual[a0] > 0 if sink_tree else residual[sister[a0]] > 0
        if open_ and not active[j]:
            active[j] = True
            queue[q_tail] = j
            q_tail = (q_tail + 1) % (n + 1)
        a = parent[j]
        if a != _TERMINAL and a != _ORPHAN and head[a] == i:
            parent[j] = _ORPHAN
            orphans[n_orphans] = j
            n_orphans += 1
    return n_orphans, q_tail


@njit(cache=True)
def _reached(n, first, head, residual, terminal, s, t):  # pragma: no cover
    side = np.zeros(n, np.bool_)
    stack = np.empty(n, np.int64)
    top = 0
    for i in range(n):
        if terminal[i] > 0 and i != s and i != t:
            side[i] = True
            stack[top] = i
            top += 1
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


@njit("b1[:](i8, i8[:], i8[:], i8[:], i8, i8)", cache=True)
def _source_side(n, tails, heads, capacity, s, t):  # pragma: no cover - compiled
    # terminal arcs become each node's terminal capacity (positive: from the source; negative:
    # to the sink, after routing min(from, to) straight through); the rest become arc pairs
    from_source = np.zeros(n, np.int64)
    to_sink = np.zeros(n, np.int64)
    inner = 0
    for k in range(len(tails)):
        u, v = tails[k], heads[k]
        if u == s and v != t and v != s:
            from_source[v] += capacity[k]
        elif v == t and u != s and u != t:
            to_sink[u] += capacity[k]
        elif u != s and u != t and v != s and v != t and u != v:
            inner += 1
    terminal = from_source - to_sink
    # arcs 2k (u -> v, its capacity) and 2k + 1 (v -> u, none), grouped by tail
    head = np.empty(2 * inner, np.int64)
    residual = np.zeros(2 * inner, np.int64)
    tail = np.empty(2 * inner, np.int64)
    k2 = 0
    for k in range(len(tails)):
        u, v = tails[k], heads[k]
        if u != s and u != t and v != s and v != t and u != v:
            head[k2], tail[k2], residual[k2] = v, u, capacity[k]
            head[k2 + 1], tail[k2 + 1] = u, v
            k2 += 2
    order = np.argsort(tail, kind="mergesort")
    rank = np.empty(2 * inner, np.int64)
    rank[order] = np.arange(2 * inner)
    first = np.zeros(n + 1, np.int64)
    for a in range(2 * inner):
        first[tail[a] + 1] += 1
    for i in range(n):
        first[i + 1] += first[i]
    arc_head = head[order]
    arc_residual = residual[order]
    sister = rank[np.arange(2 * inner) ^ 1][order]
    _grow_and_augment(n, first, arc_head, arc_residual, sister, terminal)
    return _reached(n, first, arc_head, arc_residual, terminal, s, t)
