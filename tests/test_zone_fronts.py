"""A contact zone whose edges creep a node or a few per Newton step (a body in bending
peeling off) has its moves extrapolated along ΓC (contactfem.kernel.ZoneFronts).

The unit tests drive ZoneFronts by hand on a chain whose node numbers do not follow it;
the solves compare the kernel with and without ΓC's order (``contact_edges``), which must
reach the same active set and displacement (the discrete problem's solution is unique:
S = P K⁻¹ Pᵀ is SPD) in fewer steps on bodies in bending and no more on rough contact.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from conftest import CASES, case_from, square_case_dict

from contactfem.kernel import MAX_OVERSHOOTS, ZoneFronts, solve_contact

# --- ZoneFronts by hand ------------------------------------------------------------------------

M = 30
#: Node numbers along the chain: place p holds node ORDER[p].
ORDER = np.random.default_rng(3).permutation(M)


def chain_fronts() -> ZoneFronts:
    edges = np.column_stack([ORDER[:-1], ORDER[1:]])
    edges[::2] = edges[::2, ::-1]  # either direction
    return ZoneFronts(np.random.default_rng(4).permutation(edges), M)


def at(places) -> np.ndarray:
    """Node numbers at ``places`` along the chain."""
    return ORDER[np.asarray(places, dtype=np.int64)]


def released(active: np.ndarray, places) -> np.ndarray:
    out = active.copy()
    out[at(places)] = False
    return out


def test_the_chain_is_walked_in_its_order_whatever_the_node_numbers():
    fronts = chain_fronts()
    assert fronts.enabled
    along = fronts.along if fronts.along[0] == ORDER[0] else fronts.along[::-1]
    np.testing.assert_array_equal(along, ORDER)


def test_a_creeping_edge_is_moved_ahead_by_its_step_times_run_minus_one_squared():
    """Newton releases place 10, then 11, then (after the set moved to 17) 18: the run is
    recognised at its second step (one node more: 12) and the third moves 4 more (19-22)."""
    fronts = chain_fronts()
    active = np.ones(M, dtype=bool)
    step1 = released(active, [10])
    out, moved = fronts.extend(active, step1)
    assert moved == 0 and np.array_equal(out, step1)
    step2 = released(step1, [11])
    out, moved = fronts.extend(step1, step2)
    assert moved == 1 and np.array_equal(out, released(step2, [12]))
    step3 = released(out, [13])
    out, moved = fronts.extend(released(step2, [12]), step3)
    assert moved == 4 and np.array_equal(out, released(step3, [14, 15, 16, 17]))


def test_an_edge_moving_by_a_block_is_moved_by_its_block_length_and_half_the_zone_ahead_at_most():
    """Blocks of two (places 20-21, then 18-19, leftwards, the zone ending at place 10):
    the second step moves two more (16-17: length 2 x 1², and 8 ahead / 2 = 4); at the
    third (14-15) four ahead of it allow two more (12-13), not 2 x 2² = 8."""
    fronts = chain_fronts()
    active = released(np.ones(M, dtype=bool), range(0, 10))
    step1 = released(active, [20, 21])
    fronts.extend(active, step1)
    step2 = released(step1, [18, 19])
    out, moved = fronts.extend(step1, step2)
    assert moved == 2 and np.array_equal(out, released(step2, [16, 17]))
    step3 = released(out, [14, 15])
    out, moved = fronts.extend(released(step2, [16, 17]), step3)
    assert moved == 2 and np.array_equal(out, released(step3, [12, 13]))


def test_a_step_that_is_not_all_creep_is_taken_as_newton_gives_it():
    """A patch that grows for two steps while another node changes elsewhere (a rough
    profile's patches growing and stopping) is not extrapolated."""
    fronts = chain_fronts()
    active = np.zeros(M, dtype=bool)
    active[at([5])] = True
    step1 = active.copy()
    step1[at([6])] = True
    fronts.extend(active, step1)
    step2 = step1.copy()
    step2[at([7, 20])] = True
    out, moved = fronts.extend(step1, step2)
    assert moved == 0 and np.array_equal(out, step2)


def test_an_overshoot_undoes_the_far_half_of_its_extrapolation_and_nothing_else():
    """After 14-17 were moved, Newton brings back a node of the lifted stretch (place 12)
    and releases one elsewhere (place 25): the set keeps 14-15 released and takes 16-17
    back, ignores Newton's two changes, and never extrapolates into place 17 again."""
    fronts = chain_fronts()
    active = np.ones(M, dtype=bool)
    step1 = released(active, [10])
    fronts.extend(active, step1)
    step2 = released(step1, [11])
    after2, _ = fronts.extend(step1, step2)
    step3 = released(after2, [13])
    after3, moved = fronts.extend(after2, step3)
    assert moved == 4
    newton = after3.copy()
    newton[at([12])] = True
    newton[at([25])] = False
    out, differs = fronts.extend(after3, newton)
    expected = after3.copy()
    expected[at([16, 17])] = True
    np.testing.assert_array_equal(out, expected)
    assert differs == int(np.count_nonzero(out != newton)) == 4
    assert fronts.overshoots == 1 and fronts.too_far[at(17)] and not fronts.too_far[at(16)]


def test_after_its_overshoots_the_iteration_is_newtons_alone():
    fronts = chain_fronts()
    fronts.overshoots = MAX_OVERSHOOTS
    active = np.ones(M, dtype=bool)
    step1 = released(active, [10])
    fronts.extend(active, step1)
    step2 = released(step1, [11])
    after2, moved = fronts.extend(step1, step2)
    assert moved == 1
    newton = after2.copy()
    newton[at([11])] = True
    out, differs = fronts.extend(after2, newton)
    assert differs == 0 and np.array_equal(out, newton) and not fronts.enabled


def test_chains_numbered_along_themselves_are_read_as_the_graph_search_reads_them():
    """ΓC's nodes as the contact boundary numbers them (every edge joins i and i + 1) are
    read without a graph search; under other node numbers the search finds the same runs."""
    edges = np.array([[1, 0], [1, 2], [3, 2], [3, 4], [7, 6], [7, 8], [9, 8]])  # 0-4, 5 alone, 6-9
    fast = ZoneFronts(np.random.default_rng(1).permutation(edges), 10)
    assert fast.enabled
    np.testing.assert_array_equal(fast.along, np.arange(10))
    np.testing.assert_array_equal(fast.first, [0] * 5 + [5] + [6] * 4)
    np.testing.assert_array_equal(fast.last, [4] * 5 + [5] + [9] * 4)
    relabel = np.random.default_rng(2).permutation(10)
    assert not np.all(np.abs(relabel[edges[:, 0]] - relabel[edges[:, 1]]) == 1)
    searched = ZoneFronts(relabel[edges], 10)

    def runs(fronts: ZoneFronts, names: np.ndarray) -> list[tuple[int, ...]]:
        return sorted(tuple(sorted(names[fronts.along[start:fronts.last[start] + 1]].tolist()))
                      for start in set(fronts.first.tolist()))

    assert runs(searched, np.argsort(relabel)) == runs(fast, np.arange(10)) == [(0, 1, 2, 3, 4), (5,), (6, 7, 8, 9)]


def test_a_graph_that_is_no_chain_is_not_extrapolated_along():
    branching = ZoneFronts(np.array([[0, 1], [1, 2], [1, 3], [3, 4]]), 5)
    assert not branching.enabled
    active = np.ones(5, dtype=bool)
    proposed = active.copy()
    proposed[2] = False
    assert branching.extend(active, proposed)[1] == 0
    ring = ZoneFronts(np.array([[0, 1], [1, 2], [2, 3], [3, 0]]), 4)
    assert ring.enabled and sorted(ring.along) == [0, 1, 2, 3]


# --- solves --------------------------------------------------------------------------------------


def peeling_strip(thickness: float, cells: tuple[int, int], wavenumber: int, offset: float) -> dict:
    """A 1 x ``thickness`` strip clamped on its left, resting on the plane, under the
    pressure offset + sin(k x), which lifts it where negative: a body in bending."""
    data = square_case_dict()
    data["geometry"] = {"rectangle": {"lower": [0, 0], "upper": [1, thickness]}}
    data["mesh"] = {"divisions": list(cells)}
    data["boundary"]["top"] = {"traction": [0.0, f"-1.0*({offset} + sin({wavenumber}*x))"]}
    return data


def both_ways(system):
    """The solve with ΓC's order and with Newton's update alone, both certified, and their
    answers the same set and displacement."""
    fronts = solve_contact(system)
    plain = solve_contact(replace(system, contact_edges=None))
    for result in (fronts, plain):
        assert result.status.value == "converged" and result.certificate.passed, result.message
    np.testing.assert_array_equal(fronts.active, plain.active)
    scale = np.abs(plain.displacement).max()
    precision = max(fronts.certificate.scales["relative_precision"], plain.certificate.scales["relative_precision"])
    np.testing.assert_allclose(fronts.displacement, plain.displacement, rtol=0, atol=max(10 * precision, 1e-10) * scale)
    return fronts, plain


#: Strips 1 x thickness (cells), under the pressure offset + sin(k x), and the steps Newton's
#: update alone takes: lifting at the free end and once inside (69), twice (29), four times (70).
STRIPS = [(1e-2, (400, 4), 10, 0.3), (2e-2, (800, 4), 15, 0.3), (5e-3, (600, 3), 25, 0.4)]


@pytest.mark.parametrize("method", ["positive", "standard"])
def test_strips_peeling_off_settle_in_fewer_steps_than_newton_alone_and_in_half_of_them_in_all(method):
    from contactfem.methods import get_method
    from contactfem.solve import prepare

    steps = []
    for thickness, cells, wavenumber, offset in STRIPS:
        system = prepare(case_from(peeling_strip(thickness, cells, wavenumber, offset))).contact_system(
            get_method(method)).system
        fronts, plain = both_ways(system)
        assert fronts.iterations < plain.iterations
        assert sum(step.proposed for step in fronts.history) > 0
        assert all(step.proposed == 0 for step in plain.history)
        steps.append((fronts.iterations, plain.iterations))
    assert sum(f for f, _ in steps) <= sum(p for _, p in steps) / 2, steps


@pytest.mark.parametrize("name", ["rough", "rough_loading"])
def test_a_fragmented_rough_contact_takes_no_more_steps_with_the_order_than_without(name):
    """Hundreds of patches growing and stopping at different steps: no step is all creep,
    so the order changes nothing (11 steps both ways from a cold start)."""
    from contactfem.case import load_case
    from contactfem.methods import get_method
    from contactfem.solve import prepare

    system = prepare(load_case(CASES / f"{name}.yaml")).contact_system(get_method("positive")).system
    fronts, plain = both_ways(system)
    assert fronts.iterations <= plain.iterations
