"""Statement order of the large straight-line functions: few values live at once.

gcc keeps the statements of a straight-line C function in the order printed (its scheduler
moves them only within a short window), so the order decides how many temporaries are live
at each point, and what does not fit the 16 or 32 vector registers is spilled to the stack
and loaded back. :func:`pressure_order` is a greedy list scheduler over the dependence graph
of temporaries and output entries that, at every step, prints the ready statement that
frees the most live values (a temporary whose last reader it is), net of the one it defines;
among equals, the one that comes first in demand order (``render.demand_order``: every output
entry in turn after the temporaries it still needs), so the order is demand order wherever
no statement frees more. Every decision is by integer counts and positions: the same program
gives the same order on every machine.

Example: t0 = x + 1 is read by t2 and by the second output; t1 only by t2. Demand order
prints t0, t1, t2, the first output, then the second (t0 live until the end); pressure order
prints the second output as soon as t0 is known, then t0 is read only by t2, which frees it:

>>> import symengine as se
>>> x, y, t0, t1, t2 = se.symbols("x y t0 t1 t2")
>>> assignments = [(t0, x + 1), (t1, 2 * y), (t2, t0 * t1)]
>>> pressure_order(assignments, [(t2, t0 + 1)])
[('t', 0), ('out', 0, 1), ('t', 1), ('t', 2), ('out', 0, 0)]
"""
from __future__ import annotations

import heapq


def graph(assignments, outputs):
    """(reads of each temporary, reads of each output entry, output keys): reads are the
    sorted positions of the temporaries an expression names."""
    index = {sym: k for k, (sym, _) in enumerate(assignments)}
    reads_t = [sorted({index[a] for a in e.free_symbols if a in index}) for _, e in assignments]
    keys, reads_o = [], []
    for port, exprs in enumerate(outputs):
        for entry, e in enumerate(exprs):
            keys.append(("out", port, entry))
            reads_o.append(sorted({index[a] for a in e.free_symbols if a in index}))
    return reads_t, reads_o, keys


def _demand_rank(reads_t, reads_o) -> list:
    """Position of every node (temporaries 0..n-1, outputs n..) in demand order."""
    n = len(reads_t)
    rank = [None] * (n + len(reads_o))
    pos = 0
    for o, reads in enumerate(reads_o):
        for root in reads:
            stack = [(root, False)]
            while stack:
                k, expanded = stack.pop()
                if rank[k] is not None:
                    continue
                if expanded:
                    rank[k] = pos
                    pos += 1
                    continue
                stack.append((k, True))
                stack.extend((j, False) for j in reversed(reads_t[k]) if rank[j] is None)
        rank[n + o] = pos
        pos += 1
    # temporaries no output reads (none after CSE) go last, in their order
    for k in range(n):
        if rank[k] is None:
            rank[k] = pos
            pos += 1
    return rank


def pressure_order(assignments, outputs) -> list:
    """Statements ``("t", index)`` and ``("out", port, entry)`` in the order described in the
    module text: greedy by (values freed - value defined), ties by demand order."""
    reads_t, reads_o, keys = graph(assignments, outputs)
    n = len(reads_t)
    reads = reads_t + reads_o
    readers = [[] for _ in range(n)]
    for node, rs in enumerate(reads):
        for k in rs:
            readers[k].append(node)
    remaining = [len(r) for r in readers]          # readers not yet printed, per temporary
    waiting = [len(rs) for rs in reads]             # operands not yet printed, per node
    rank = _demand_rank(reads_t, reads_o)
    done = [False] * len(reads)

    def score(node):
        return sum(1 for k in reads[node] if remaining[k] == 1) - (1 if node < n else 0)

    heap = [(-score(v), rank[v], v) for v in range(len(reads)) if waiting[v] == 0]
    heapq.heapify(heap)
    order = []
    while heap:
        neg, _, v = heapq.heappop(heap)
        if done[v] or -neg != score(v):
            continue                                # stale entry: v was re-pushed with its new score
        done[v] = True
        order.append(("t", v) if v < n else keys[v - n])
        for k in reads[v]:
            remaining[k] -= 1
            if remaining[k] == 1:                    # its last reader now frees it
                for u in readers[k]:
                    if not done[u] and waiting[u] == 0:
                        heapq.heappush(heap, (-score(u), rank[u], u))
        if v < n:
            for u in readers[v]:
                waiting[u] -= 1
                if waiting[u] == 0:
                    heapq.heappush(heap, (-score(u), rank[u], u))
    if len(order) != len(reads):
        raise ValueError("dependence cycle among temporaries")
    return order


def max_live(order, assignments, outputs) -> tuple[int, float]:
    """(most temporaries live at once, mean live over the statements) of an order: a
    temporary is live from its statement to its last reader's."""
    reads_t, reads_o, keys = graph(assignments, outputs)
    n = len(reads_t)
    node = {("t", k): k for k in range(n)}
    node.update({key: n + o for o, key in enumerate(keys)})
    reads = reads_t + reads_o
    remaining = [0] * n
    for rs in reads:
        for k in rs:
            remaining[k] += 1
    live = peak = total = 0
    for s in order:
        v = node[s]
        for k in reads[v]:
            remaining[k] -= 1
            live -= remaining[k] == 0
        if v < n:
            live += 1
        peak = max(peak, live)
        total += live
    return peak, total / max(len(order), 1)
