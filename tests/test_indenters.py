"""Rigid indenters: curved obstacles (circle, polyline, profile) and an obstacle driven by a
prescribed advance or pushed by a force. What theory fixes is checked: a straight polyline
or profile is the segment, a moved line is the line put there, force and displacement
control are one problem, the reaction of a pushed obstacle is its force."""

from __future__ import annotations

import json

import numpy as np
import pytest
import yaml
from conftest import case_from, make_runner

from contactfem.cli import main
from contactfem.solve import solve_case


def block(obstacle: dict, divisions=(24, 8), **extra) -> dict:
    """A 2 x 0.5 block, bottom clamped, top the contact part, pressed from above."""
    return {
        "title": "block under an indenter",
        "geometry": {"rectangle": {"lower": [-1, -0.5], "upper": [1, 0]}},
        "mesh": {"divisions": list(divisions)},
        "material": {"E": 1.0e6, "nu": 0.3},
        "boundary": {"bottom": "clamped", "left": "free", "right": "free", "top": "contact"},
        "obstacle": obstacle,
        **extra,
    }


def relative(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.abs(a - b).max() / np.abs(b).max())


def test_a_straight_polyline_and_a_straight_profile_are_the_segment():
    """The polyline through the segment's two ends (and through a midpoint on it), and a
    profile of constant height, pose the segment's discrete problem: same nodes, gaps and
    normals, so the same solution to round-off."""
    ends = [[0.6, -0.002], [-0.6, -0.002]]
    segment = solve_case(case_from(block({"segment": ends})))
    for obstacle in ({"polyline": ends}, {"polyline": [ends[0], [0.1, -0.002], ends[1]]},
                     {"profile": {"heights": [0.002, 0.002, 0.002], "spacing": 0.6, "start": -0.6,
                                  "direction": [-1, 0]}}):
        other = solve_case(case_from(block(obstacle)))
        np.testing.assert_array_equal(other.problem.contact.nodes, segment.problem.contact.nodes)
        np.testing.assert_allclose(other.problem.contact.gap, segment.problem.contact.gap, rtol=0, atol=1e-15)
        assert relative(other.solution.displacement, segment.solution.displacement) < 1e-10
        assert relative(other.solution.contact.nodal_force, segment.solution.contact.nodal_force) < 1e-10


def test_a_flat_obstacle_keeps_one_normal_in_every_frame():
    """A flat obstacle's per-node normals are its one normal, bit for bit: the frames, and
    so every flat result, are those of the single normal."""
    result = solve_case(case_from(block({"points": [[1, 0.001], [-1, 0.001]], "motion": {"direction": [0, -1], "displacement": 0.003}})))
    contact = result.problem.contact
    assert np.array_equal(contact.normals, np.tile(contact.normal, (len(contact.nodes), 1)))
    assert result.solution.contact.normals is None


def test_a_moved_line_is_the_line_put_there():
    """Small deformations: a line moved by δ d poses the line at its new place. The block's
    field is the same to round-off, the report records the advance."""
    moved = solve_case(case_from(block({"points": [[1, 0.001], [-1, 0.001]],
                                        "motion": {"direction": [0, -1], "displacement": 0.003}})))
    placed = solve_case(case_from(block({"points": [[1, -0.002], [-1, -0.002]]})))
    assert relative(moved.solution.displacement, placed.solution.displacement) < 1e-10
    np.testing.assert_allclose(moved.solution.contact.gap, placed.solution.contact.gap, rtol=0, atol=1e-15)


def circle_case(motion: dict, **extra) -> dict:
    return block({"circle": {"center": [0.0, 1.0], "radius": 1.0}, "motion": motion}, divisions=(40, 10), **extra)


def counting_kernel_solves(monkeypatch) -> list:
    """Every call of the contact kernel by :func:`solve_case`, recorded."""
    import contactfem.solve as solve_module

    calls = []
    kernel = solve_module.solve_contact

    def counted(*args, **kwargs):
        result = kernel(*args, **kwargs)
        calls.append(result)
        return result

    monkeypatch.setattr(solve_module, "solve_contact", counted)
    return calls


def test_force_and_displacement_control_agree_and_the_reaction_is_the_force(monkeypatch):
    """The pushed obstacle's advance is one unknown of one solve, its equation the
    obstacle's equilibrium: the reaction is the force to round-off, and the advance it
    finds, prescribed, poses the same problem (same active set, same linear system)."""
    driven = solve_case(case_from(circle_case({"direction": [0, -1], "displacement": 0.004})))
    drive = driven.problem.drive
    force = drive.reaction(driven.kernel.nodal_force, driven.problem.contact.normals)
    assert force > 0 and driven.kernel.active.sum() >= 3
    calls = counting_kernel_solves(monkeypatch)
    pushed = solve_case(case_from(circle_case({"direction": [0, -1], "force": force})))
    assert len(calls) == 1 and pushed.kernel.factorizations == 1 and pushed.kernel.iterations <= 3
    reaction = pushed.problem.drive.reaction(pushed.kernel.nodal_force, pushed.problem.contact.normals)
    assert abs(reaction - force) <= 1e-10 * force
    assert abs(pushed.problem.drive.advance - 0.004) <= 1e-9 * 0.004
    assert relative(pushed.solution.displacement, driven.solution.displacement) < 1e-9
    at_its_advance = solve_case(case_from(circle_case({"direction": [0, -1],
                                                       "displacement": pushed.problem.drive.advance})))
    assert relative(pushed.solution.displacement, at_its_advance.solution.displacement) < 1e-9
    assert relative(pushed.kernel.nodal_force, at_its_advance.kernel.nodal_force) < 1e-9
    # Normals are the circle's at each node's closest point, pointing into the disk.
    contact = driven.problem.contact
    radial = contact.positions - np.array([0.0, 1.0])
    np.testing.assert_allclose(contact.normals, -radial / np.hypot(*radial.T)[:, None], atol=1e-15)
    np.testing.assert_allclose(contact.gap, np.hypot(*radial.T) - 1.0, atol=1e-15)


def test_a_pushed_obstacle_balances_its_force_with_the_body_loaded_too():
    """A traction on the body along the motion: the obstacle's own equilibrium still holds
    (the contact force on it is its force, not the supports' reaction), and the advance
    found, prescribed, gives the same field."""
    def loaded(motion: dict) -> dict:
        data = circle_case(motion)
        data["boundary"]["left"] = {"traction": [0.0, -300.0]}
        return data

    pushed = solve_case(case_from(loaded({"direction": [0, -1], "force": 2500.0})))
    drive = pushed.problem.drive
    assert abs(drive.reaction(pushed.kernel.nodal_force, pushed.problem.contact.normals) - 2500.0) <= 1e-10 * 2500.0
    driven = solve_case(case_from(loaded({"direction": [0, -1], "displacement": drive.advance})))
    assert relative(pushed.solution.displacement, driven.solution.displacement) < 1e-9


def rollers(data: dict) -> dict:
    data["boundary"].update(bottom={"displacement": [None, 0.0]}, left={"displacement": [0.0, None]})
    return data


def half_block(data: dict) -> dict:
    data["geometry"] = {"rectangle": {"lower": [0, -0.5], "upper": [1, 0]}}
    data["boundary"]["left"] = "symmetry"
    return data


def lifted(data: dict) -> dict:
    data["obstacle"]["circle"]["center"] = [0.0, 1.01]
    return data


@pytest.mark.parametrize("direction, pose, force", [
    ([-0.3, -1.0], lambda data: data, 2000.0),  # held components along x and y both follow
    ([-0.3, -1.0], rollers, 2000.0),  # each held node one component, of either axis
    ([0.0, -1.0], half_block, 1000.0),  # a symmetry line along the motion
    ([0.0, -1.0], lifted, 2000.0),  # every gap open at rest: contact alone holds the push
])
def test_a_pushed_obstacle_is_the_driven_one_at_its_advance(direction, pose, force):
    """Whichever held components carry the advance, the pushed obstacle's reaction is its
    force and the advance it finds, prescribed, gives the same field."""
    pushed = solve_case(case_from(pose(circle_case({"direction": direction, "force": force}))))
    drive = pushed.problem.drive
    assert abs(drive.reaction(pushed.kernel.nodal_force, pushed.problem.contact.normals) - force) <= 1e-10 * force
    assert drive.advance > 0 and pushed.kernel.factorizations == 1
    driven = solve_case(case_from(pose(circle_case({"direction": direction, "displacement": drive.advance}))))
    assert relative(pushed.solution.displacement, driven.solution.displacement) < 1e-9
    np.testing.assert_array_equal(pushed.kernel.active, driven.kernel.active)


def test_the_iterative_backend_finds_the_same_advance():
    """CG with algebraic multigrid solves the same system, the advance among its unknowns:
    the same advance and field as the factorisation, to CG's tolerance."""
    pytest.importorskip("pyamg")
    direct = solve_case(case_from(circle_case({"direction": [0, -1], "force": 2000.0})))
    data = circle_case({"direction": [0, -1], "force": 2000.0})
    data["solver"] = {"backend": "amg"}
    iterative = solve_case(case_from(data))
    drive = iterative.problem.drive
    assert abs(drive.reaction(iterative.kernel.nodal_force, iterative.problem.contact.normals) - 2000.0) <= 1e-10 * 2000
    assert abs(drive.advance - direct.problem.drive.advance) <= 1e-9 * direct.problem.drive.advance
    assert relative(iterative.solution.displacement, direct.solution.displacement) < 1e-9


def test_a_pushed_obstacle_along_a_load_path_is_each_single_solve():
    """The force is scaled along the path like every prescribed value: each of 5 steps,
    one solve of the path with its one factorisation, is the single solve at its force."""
    from contactfem.solve import solve_load_path

    force, factors = 2500.0, [0.2, 0.4, 0.6, 0.8, 1.0]
    path = solve_load_path(case_from(circle_case({"direction": [0, -1], "force": force},
                                                 load_path={"factors": factors})))
    assert path.factorizations == 1
    for factor, step in zip(factors, path.steps):
        single = solve_case(case_from(circle_case({"direction": [0, -1], "force": factor * force})))
        drive = step.problem.drive
        assert drive.force == factor * force
        assert abs(drive.reaction(step.kernel.nodal_force, step.problem.contact.normals) - factor * force) \
            <= 1e-10 * factor * force
        assert abs(drive.advance - single.problem.drive.advance) <= 1e-9 * single.problem.drive.advance
        assert relative(step.solution.displacement, single.solution.displacement) < 1e-9
        np.testing.assert_array_equal(step.kernel.active, single.kernel.active)


def test_a_moving_obstacle_along_a_load_path_scales_its_advance(tmp_path):
    """The advance is a prescribed value: a path's last step at factor 1 is the single solve."""
    from contactfem.solve import solve_load_path

    data = circle_case({"direction": [0, -1], "displacement": 0.004}, load_path={"factors": [0.5, 1.0]})
    path = solve_load_path(case_from(data))
    single = solve_case(case_from(circle_case({"direction": [0, -1], "displacement": 0.004})))
    assert relative(path.steps[-1].solution.displacement, single.solution.displacement) < 1e-10
    assert path.steps[0].problem.drive.advance == 0.002


def test_the_circle_solve_writes_its_obstacle(tmp_path):
    from contactfem.io import read_hdf5

    path = tmp_path / "indenter.yaml"
    path.write_text(yaml.safe_dump(circle_case({"direction": [0, -1], "displacement": 0.004})), encoding="utf-8")
    out = tmp_path / "out"
    result = make_runner().invoke(main, ["solve", str(path), "--out", str(out), "--quiet", "--plot"])
    assert result.exit_code == 0, result.stderr
    report = json.loads((out / "report.json").read_text(encoding="utf-8"))
    assert report["obstacle"]["kind"] == "circle" and report["obstacle"]["small_deformations"] is True
    assert report["obstacle"]["motion"]["advance"] == 0.004
    contact = read_hdf5(out / "solution.h5")["contact"]
    q, x = contact["obstacle_points"], read_hdf5(out / "solution.h5")["mesh"]["points"][contact["nodes"]]
    np.testing.assert_allclose(np.hypot(*(q - [0.0, 1.0]).T), 1.0, atol=1e-12)
    np.testing.assert_allclose(np.einsum("ij,ij->i", q - x, contact["normals"]) - 0.004 * contact["normals"][:, 1],
                               contact["gap"], atol=1e-12)
    header = (out / "contact.csv").read_text(encoding="utf-8").splitlines()[0]
    assert all(name in header for name in ("obstacle_x", "obstacle_y", "normal_x", "normal_y"))


@pytest.mark.parametrize("obstacle, fragment", [
    ({"circle": {"center": [0, 1], "radius": 0}}, "obstacle.circle.radius"),
    ({"circle": {"center": [0, 1], "radius": -1}}, "obstacle.circle.radius"),
    ({"polyline": [[1, 0.1], [-1, 0.1], [0, -0.1], [0, 0.5]]}, "obstacle.polyline"),
    ({"polyline": [[1, 0.1], [1, 0.1], [-1, 0.1]]}, "obstacle.polyline"),
    ({"circle": {"center": [0, -2], "radius": 1}}, "obstacle.circle: no contact node"),
    ({"polyline": [[5, 0.1], [3, 0.1]]}, "obstacle"),
    ({"polyline": [[0.5, 0.0], [0.0, -0.5 * 0.25 + 0.0], [-0.5, 0.0]][::-1]}, "equidistant"),
    ({"circle": {"center": [0, 1], "radius": 1}, "motion": {"direction": [0, 0], "displacement": 1}},
     "obstacle.motion.direction"),
    ({"circle": {"center": [0, 1], "radius": 1}, "motion": {"direction": [0, -1], "force": 1, "displacement": 1}},
     "obstacle.motion"),
    ({"circle": {"center": [0, 1.1], "radius": 1}, "motion": {"direction": [0, 1], "force": 1}},
     "obstacle.motion.direction"),
    ({"polyline": [[1, 0.1], [-1, 0.1]], "motion": {"direction": [1, 0], "displacement": 0.2}},
     "obstacle.motion.direction"),
])
def test_bad_indenters_are_refused_naming_the_key(tmp_path, obstacle, fragment):
    path = tmp_path / "indenter.yaml"
    path.write_text(yaml.safe_dump(block(obstacle)), encoding="utf-8")
    result = make_runner().invoke(main, ["solve", str(path), "--out", str(tmp_path / "out")])
    assert result.exit_code == 2, (result.output, result.stderr)
    lines = result.stderr.splitlines()
    assert len(lines) == 1 and "indenter.yaml" in lines[0] and fragment in lines[0], lines
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("boundary, fragment", [
    ({"left": {"platen": {"force": 1.0}}}, "obstacle.motion: a moving obstacle with a platen"),
    ({"left": "symmetry"}, "crosses a symmetry line"),
])
def test_what_a_pushed_obstacle_does_not_pose_is_refused(tmp_path, boundary, fragment):
    """Supports that the advance cannot carry: a platen (an advance of its own), a symmetry
    line the motion crosses."""
    data = circle_case({"direction": [-1, -1], "force": 10.0}, load_path={"factors": [0.5, 1]})
    data["boundary"].update(boundary)
    path = tmp_path / "indenter.yaml"
    path.write_text(yaml.safe_dump(data), encoding="utf-8")
    result = make_runner().invoke(main, ["solve", str(path), "--out", str(tmp_path / "out")])
    assert result.exit_code == 2, (result.output, result.stderr)
    lines = result.stderr.splitlines()
    assert len(lines) == 1 and "indenter.yaml" in lines[0] and fragment in lines[0], lines
    assert not (tmp_path / "out").exists()


def test_the_archive_reader_checks_a_curved_obstacles_normals(tmp_path):
    """solution.h5 is untrusted input: non-unit normals, or normals without their closest
    points, are refused naming the dataset."""
    import h5py

    from contactfem.errors import ArchiveError
    from contactfem.io import read_hdf5

    path = tmp_path / "indenter.yaml"
    path.write_text(yaml.safe_dump(circle_case({"direction": [0, -1], "displacement": 0.004})), encoding="utf-8")
    out = tmp_path / "out"
    assert make_runner().invoke(main, ["solve", str(path), "--out", str(out), "--quiet"]).exit_code == 0
    with h5py.File(out / "solution.h5", "r+") as f:
        f["/contact/normals"][0] = (2.0, 0.0)
    with pytest.raises(ArchiveError, match="/contact/normals"):
        read_hdf5(out / "solution.h5")
    with h5py.File(out / "solution.h5", "r+") as f:
        del f["/contact/obstacle_points"]
    with pytest.raises(ArchiveError, match="/contact/obstacle_points"):
        read_hdf5(out / "solution.h5")


def test_a_rounded_punch_meets_the_half_plane_consistency_condition():
    """A flat punch of half-width a = 0.5 with corners rounded to R = 0.2, pressed 0.013 into
    an 8 x 4 block: half-plane theory (Ciavarella, Hills & Monno 1998) bounds the pressure at
    ±b when P = E* b² (π − 2φ0 − sin 2φ0) / (4R), φ0 = arcsin(a / b). The constraint along the
    punch's normal keeps u_x · g′ in the gap, which that theory drops: the zone on the
    reference abscissa ends U(b) (the surface's inward slide) beyond where the material meets
    the punch. Less U, b − a (≈ 0.019, five elements) is the theory's within 4% (the
    benchmark's finer meshes and larger blocks: within 2.1%); without, it is 5–12% wider."""
    from scipy.optimize import brentq

    from contactfem.validation import _zone_end

    a, radius, modulus = 0.5, 0.2, 1.0e6 / (1 - 0.3**2)
    angle = np.linspace(0.0, np.pi / 2, 257)
    corner = np.stack([a + radius * np.sin(angle), radius * (1 - np.cos(angle))], axis=1)
    vertices = np.concatenate([corner[::-1], corner * [-1, 1]]).tolist()
    data = {
        "title": "rounded punch",
        "geometry": {"polygon": {"vertices": [[-4, -4], [4, -4], [4, 0], [1, 0], [-1, 0], [-4, 0]],
                                 "edges": ["base", "side", "free", "surface", "free", "side"]}},
        "mesh": {"size": 0.5, "contact_size": 0.004},
        "material": {"E": 1.0e6, "nu": 0.3},
        "boundary": {"base": "clamped", "side": "free", "free": "free", "surface": "contact"},
        "obstacle": {"polyline": vertices, "motion": {"direction": [0, -1], "displacement": 0.013}},
    }
    result = solve_case(case_from(data))
    problem, contact = result.problem, result.solution.contact
    s, active = problem.contact.abscissa, np.flatnonzero(contact.active)
    b = 0.5 * (_zone_end(s, contact.multiplier, active.max(), inward=-1)
               - _zone_end(s, contact.multiplier, active.min(), inward=+1))
    force = problem.drive.reaction(contact.nodal_force, problem.contact.normals)

    def theory(width: float) -> float:
        phi = np.arcsin(a / width)
        return modulus * width**2 / (4 * radius) * (np.pi - 2 * phi - np.sin(2 * phi))

    expected = brentq(lambda width: theory(width) - force, a * (1 + 1e-12), a + radius, xtol=1e-14)
    x = problem.contact.positions[:, 0]
    order = np.argsort(x)
    slide = -np.interp(b, x[order], result.solution.displacement.reshape(-1, 2)[problem.contact.nodes[order], 0])
    assert 0.05 < (b - a) / (expected - a) - 1 < 0.12
    assert abs((b - slide - a) / (expected - a) - 1) < 0.04
