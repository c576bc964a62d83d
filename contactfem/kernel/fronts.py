"""Zone fronts: a contact zone edge that creeps a node or a few per Newton step, moved ahead.

A proposer of the kernel (:mod:`contactfem.kernel.proposers`): it watches Newton's updates
along ΓC and, once an edge has moved the same way for :data:`CREEP_RUN` steps, proposes
the set with that edge carried further, undoing half of any move that overshot.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

#: Consecutive steps a zone edge must have moved the same way before its move is
#: extrapolated (see :class:`ZoneFronts`): from the second step of a creep on. Each step
#: waited is a step of creep left to Newton's update, which slender strips pay for most.
CREEP_RUN = 2
#: Overshoots (see :class:`ZoneFronts`) after which a solve goes on with Newton's update
#: alone; each halves the extrapolations that overshot.
MAX_OVERSHOOTS = 8
#: The most nodes one extrapolation moves a zone edge by.
MAX_EXTRAPOLATION = 4096
#: An extrapolation takes at most this share of the nodes ahead of it in the state it
#: leaves, so that two edges closing on a patch from both sides leave something of it (a
#: wavy traction's hundreds of shrinking patches were otherwise released whole).
SHARE_AHEAD = 2
#: ΓC chains beyond which no order along them is built (a contact part of thousands of
#: separate edges has no zone edge to creep): one graph search per chain.
MAX_CHAINS = 256


class ZoneFronts:
    """The edges of the contact zone along ΓC, to recognise a zone that creeps and move it
    ahead.

    A body in bending (a strip peeling off, a plate lifting at its ends) moves each zone
    edge by a node or a few per Newton step: releasing a node puts the next in tension,
    and plain Newton takes about as many steps as the edge crosses nodes.

    Each step's changes are taken as blocks, stretches of consecutive ΓC nodes changing
    the same way. A block whose neighbour on one side changed the same way at the last
    step (and stays so) continues a run; on a step whose every block continues one, each
    block from the :data:`CREEP_RUN`-th step of its run on is carried on beyond its far
    end by its own length times (run − 1)² nodes, through nodes in the state it leaves
    (at most a :data:`SHARE_AHEAD`-th of those ahead of it): the edge crosses n nodes in
    about (3n)^⅓ steps. Doubling instead (a galloping search)
    overshot more on strips lifting in several places. An extrapolation overshot when, at
    the next step, Newton changes a node of the stretch of nodes in one state that holds
    it (a strip released too far sags back onto the obstacle within its lifted span);
    then the far half of each such extrapolation is undone instead of taking Newton's
    update, whose answer to a body over-released is to bring back far more than the
    overshoot, and its farthest node is never extrapolated into again: a bisection. After
    :data:`MAX_OVERSHOOTS` of them the solve goes on with Newton's update alone, so that
    the iteration's termination (the cycle safeguard, the least-index rule) is kept.
    Strips too slender for double precision cycle with or without it: a coarser level's
    prediction settles them (:data:`contactfem.kernel.proposers.STALL_ITERATIONS`).
    """

    def __init__(self, edges: np.ndarray, m: int):
        from scipy.sparse.csgraph import connected_components, depth_first_order

        self.enabled = False
        self.overshoots = 0
        self.last_change = np.zeros(m, dtype=np.int8)
        self.run = np.zeros(m, dtype=np.int64)
        self.moved = self.moved_owner = self.moved_offset = np.zeros(0, dtype=np.int64)
        self.too_far = np.zeros(m, dtype=bool)
        edges = np.asarray(edges, dtype=np.int64).reshape(-1, 2)
        edges = edges[edges[:, 0] != edges[:, 1]]
        if m < 3 or len(edges) == 0 or np.bincount(edges.ravel(), minlength=m).max() > 2:
            return
        if np.all(np.abs(edges[:, 0] - edges[:, 1]) == 1):
            # Every edge joins nodes i and i + 1 (ΓC's nodes numbered along it, as the contact
            # boundary numbers them): the chains are runs of consecutive nodes, each walked
            # upwards, what the graph search below finds at a tenth of its cost.
            linked = np.zeros(m, dtype=bool)  # linked[i]: an edge joins i and i + 1
            linked[edges.min(axis=1)] = True
            starts = np.flatnonzero(np.r_[True, ~linked[:-1]])
            if len(starts) > MAX_CHAINS:
                return
            along, lengths = np.arange(m), np.diff(np.r_[starts, m])
        else:
            graph = sp.csr_matrix((np.ones(len(edges)), (edges[:, 0], edges[:, 1])), shape=(m, m))
            graph = ((graph + graph.T) > 0).astype(np.int8).tocsr()
            count, labels = connected_components(graph, directed=False)
            if count > MAX_CHAINS:
                return
            # Each chain is walked from an end (a node of one edge), or from any node of a loop.
            start = np.zeros(count, dtype=np.int64)
            start[labels[::-1]] = np.arange(m)[::-1]  # each chain's lowest node
            ends = np.flatnonzero(np.diff(graph.indptr) == 1)
            start[labels[ends[::-1]]] = ends[::-1]
            orders = [depth_first_order(graph, node, directed=False, return_predecessors=False) for node in start]
            along, lengths = np.concatenate(orders), np.array([len(order) for order in orders])
        #: The contact nodes chain after chain, each chain in its order; ``where[i]`` is node
        #: i's place in it and ``first``/``last`` the places its chain spans.
        self.along = along
        self.where = np.empty(m, dtype=np.int64)
        self.where[along] = np.arange(m)
        starts = np.concatenate([[0], np.cumsum(lengths)[:-1]])
        self.first = np.repeat(starts, lengths)
        self.last = np.repeat(starts + lengths - 1, lengths)
        self.enabled = True

    def forget(self) -> None:
        """Start every run again (a step whose set came from elsewhere than Newton's update)."""
        self.last_change[:] = 0
        self.run[:] = 0
        self.moved = self.moved_owner = self.moved_offset = np.zeros(0, dtype=np.int64)

    def extend(self, active: np.ndarray, proposed: np.ndarray) -> tuple[np.ndarray, int]:
        """Newton's proposed set with every creeping zone edge moved ahead, and how many
        nodes that changed beyond Newton's update; records this step's changes."""
        if not self.enabled:
            return proposed, 0
        change = proposed.astype(np.int8) - active.astype(np.int8)
        # An extrapolation overshot if Newton changes any node of the stretch of nodes in one
        # state that holds it: a node of the stretch itself, or one further on (a strip
        # released too far sags onto the obstacle in the middle of its lifted span).
        if len(self.moved):
            stretch, stretch_start, _ = self._stretches(active)
            changing = np.bincount(stretch, weights=change[self.along] != 0, minlength=len(stretch_start)) > 0
            back = changing[stretch[self.where[self.moved]]]
            if back.any():
                return self._bisect(active, proposed, back)
        # This step's changes as blocks: stretches of consecutive places along a chain that
        # change the same way (a creeping edge moves by one node or a few per step).
        places = np.sort(self.where[np.flatnonzero(change)])
        nodes = self.along[places]
        starts = np.ones(len(places), dtype=bool)
        starts[1:] = ((places[1:] != places[:-1] + 1) | (self.first[places[1:]] != self.first[places[:-1]])
                      | (change[nodes[1:]] != change[nodes[:-1]]))
        low = places[starts]
        high = places[np.r_[np.flatnonzero(starts)[1:] - 1, len(places) - 1]] if len(places) else low
        way = change[self.along[low]]

        def continued(outside: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            """Whether the place next to each block (``outside``) changed the same way at the
            last step and stays so, and the node there."""
            inside = (outside >= self.first[low]) & (outside <= self.last[low])
            node = self.along[np.where(inside, outside, low)]
            return inside & (self.last_change[node] == way) & (change[node] == 0), node

        below, below_node = continued(low - 1)
        above, above_node = continued(high + 1)
        edge = below ^ above  # a run reaches a block from one side: it moves away from there
        run = np.where(edge, self.run[np.where(below, below_node, above_node)] + 1, 1)
        self.last_change[:] = 0
        self.last_change[nodes] = change[nodes]
        self.run[:] = 0
        self.run[nodes] = np.repeat(run, high - low + 1)
        self.moved = self.moved_owner = self.moved_offset = np.zeros(0, dtype=np.int64)
        fronts = np.flatnonzero(edge & (run >= CREEP_RUN))
        # Only a step that is all creep: patches that grow for two steps and stop (a rough
        # profile's cold start) are not fronts.
        if len(fronts) == 0 or not edge.all():
            return proposed, 0
        # Beyond each such block, its own length times (run − 1)² places, as far as they run
        # through nodes in the state the block leaves (at most MAX_EXTRAPOLATION, and a
        # SHARE_AHEAD-th of that state's stretch ahead of the block).
        stretch, stretch_start, stretch_end = self._stretches(active)
        length = high[fronts] - low[fronts] + 1
        direction = np.where(below[fronts], 1, -1)
        beyond = np.where(below[fronts], high[fronts], low[fronts])
        ahead = np.where(below[fronts], stretch_end[stretch[beyond]] - beyond, beyond - stretch_start[stretch[beyond]])
        reach = np.minimum(np.minimum(length * np.minimum(run[fronts] - 1, 64) ** 2, MAX_EXTRAPOLATION),
                           ahead // SHARE_AHEAD)
        fronts, direction, beyond, reach = fronts[reach > 0], direction[reach > 0], beyond[reach > 0], reach[reach > 0]
        if len(fronts) == 0:
            return proposed, 0
        owner = np.repeat(np.arange(len(fronts)), reach)
        offset = np.arange(len(owner)) - np.repeat(np.cumsum(reach) - reach, reach) + 1
        target_place = beyond[owner] + direction[owner] * offset
        ok = (target_place >= self.first[beyond[owner]]) & (target_place <= self.last[beyond[owner]])
        target = self.along[np.where(ok, target_place, beyond[owner])]
        leaving = way[fronts] < 0  # a released block leaves the active state
        ok &= (active[target] == leaving[owner]) & (change[target] == 0) & ~self.too_far[target]
        # Only the unbroken stretch next to each block: up to its first place that fails.
        blocked = np.where(ok, np.iinfo(np.int64).max, offset)
        first_blocked = np.minimum.reduceat(blocked, np.cumsum(reach) - reach)
        keep = ok & (offset < first_blocked[owner])
        target, owner = target[keep], owner[keep]
        if len(target) == 0:
            return proposed, 0
        extended = proposed.copy()
        extended[target] = ~leaving[owner]
        self.moved, self.moved_owner, self.moved_offset = target, owner, offset[keep]
        self.last_change[target] = way[fronts][owner]
        self.run[target] = run[fronts][owner]
        return extended, len(target)

    def _stretches(self, active: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The stretches of consecutive places in one state along each chain: each place's
        stretch, and each stretch's first and last place."""
        state = active[self.along]
        starts = np.ones(len(state), dtype=bool)
        starts[1:] = (state[1:] != state[:-1]) | (self.first[1:] != self.first[:-1])
        first = np.flatnonzero(starts)
        return np.cumsum(starts) - 1, first, np.r_[first[1:] - 1, len(state) - 1]

    def _bisect(self, active: np.ndarray, proposed: np.ndarray, back: np.ndarray) -> tuple[np.ndarray, int]:
        """The set after an overshoot: the far half of each stretch some of whose nodes
        Newton changes back is undone (its far end never extrapolated into again), the near
        half kept; nothing else changes at this step (Newton's update beside an overshoot answers
        the overshoot, not the edge). Counted as many nodes as it differs from Newton's."""
        self.overshoots += 1
        self.last_change[:] = 0
        self.run[:] = 0
        owners = np.unique(self.moved_owner[back])
        in_overshoot = np.isin(self.moved_owner, owners)
        reach = np.zeros(int(self.moved_owner.max()) + 1, dtype=np.int64)
        np.maximum.at(reach, self.moved_owner, self.moved_offset)
        # Never empty: the farthest node of each such stretch is in its far half.
        far = in_overshoot & (self.moved_offset > reach[self.moved_owner] // 2)
        if self.overshoots > MAX_OVERSHOOTS:
            self.enabled = False
            self.moved = np.zeros(0, dtype=np.int64)
            return proposed, 0
        result = active.copy()
        result[self.moved[far]] = ~result[self.moved[far]]
        # The stretch's far end went too far: no extrapolation reaches it again (the edge
        # lies before it, perhaps in the half undone, which Newton or a shorter
        # extrapolation from the kept half then reaches).
        self.too_far[self.moved[far & (self.moved_offset == reach[self.moved_owner])]] = True
        self.moved, self.moved_owner, self.moved_offset = (self.moved[~far], self.moved_owner[~far],
                                                           self.moved_offset[~far])
        self.last_change[self.moved] = (active[self.moved].astype(np.int8) * 2 - 1)
        return result, int(np.count_nonzero(result != proposed))
