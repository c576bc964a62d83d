"""The geometry as a user writes it: arcs by centre, radius and angles, "did you mean" for a
mistyped key, holes checked against the curved boundary itself, and "faces the obstacle"
decided on the geometry (an arc by its whole range of normals) rather than on the mesh."""

from __future__ import annotations

import copy

import pytest
import yaml
from conftest import CASES

from contactfem.case import parse_case
from contactfem.errors import CaseError
from contactfem.solve import prepare

HERTZ = yaml.safe_load((CASES / "hertz.yaml").read_text(encoding="utf-8"))


def _hertz(**changes) -> dict:
    data = copy.deepcopy(HERTZ)
    data["mesh"] = {"size": 0.1, "contact_size": 0.02, "grading": 0.3}
    for key, value in changes.items():
        data[key] = value
    return data


def _parse(data: dict):
    return parse_case(yaml.safe_dump(data, sort_keys=False), source="geometry.yaml")


def _refusal(data: dict) -> str:
    with pytest.raises(CaseError) as caught:
        prepare(_parse(data))
    return str(caught.value)


def _by_angles(vertices, arc: dict) -> dict:
    return {"polygon": {"vertices": vertices, "edges": ["top", {"name": "rim", "arc": arc}]}}


def test_an_arc_by_angles_is_the_arc_by_centre_and_direction():
    by_centre = prepare(_parse(_hertz()))
    by_angles = prepare(_parse(_hertz(geometry=_by_angles([None, None], {"center": [0, 1], "radius": 1,
                                                                        "angles": [180, 360]}))))
    assert by_angles.mesh.n_points == by_centre.mesh.n_points
    assert (by_angles.contact.nodes == by_centre.contact.nodes).all()


def test_listed_end_vertices_must_lie_at_the_arcs_ends():
    near = _parse(_hertz(geometry=_by_angles([[1.0000001, 1], [-1, 1]], {"center": [0, 1], "radius": 1,
                                                                         "angles": [180, 360]})))
    assert near.geometry.outer.vertices[0].tolist() == [1.0, 1.0]  # moved onto the arc
    message = _refusal(_hertz(geometry=_by_angles([[1, 1], [-1, 1]], {"center": [0, 1], "radius": 1,
                                                                      "angles": [180, 350]})))
    assert "geometry.polygon.vertices[0]" in message and "350 degrees" in message
    message = _refusal(_hertz(geometry=_by_angles([None, None], {"center": [0, 1], "radius": 1,
                                                                 "angles": [180, 360], "direction": "cw"})))
    assert "geometry.polygon.edges[1].arc.direction" in message and "contradicts" in message
    message = _refusal(_hertz(geometry={"polygon": {"vertices": [None, [-1, 1]], "edges": ["top", "rim"]}}))
    assert "geometry.polygon.vertices[0]" in message and "null only at an end of an arc" in message


@pytest.mark.parametrize("change, suggestion", [
    (lambda d: d.update(materail=d.pop("material")), "materail: unknown key (did you mean material?)"),
    (lambda d: d["obstacle"].update(normals=d["obstacle"].pop("normal")), "did you mean normal?"),
    (lambda d: d["mesh"].update(contact_sise=0.01), "did you mean contact_size?"),
])
def test_a_mistyped_key_gets_a_suggestion(change, suggestion):
    data = _hertz()
    change(data)
    assert suggestion in _refusal(data)


def test_holes_are_checked_against_the_arcs_themselves():
    """A hole in the half-disk's round bulge lies outside the straight polygon through its
    vertices but inside the body: accepted; one crossing the arc is refused, naming it."""
    inside = _hertz()
    inside["geometry"]["polygon"]["holes"] = [{"circle": {"center": [0, 0.3], "radius": 0.15}}]
    problem = prepare(_parse(inside))
    assert "hole" in problem.mesh.part_names
    crossing = _hertz()
    crossing["geometry"]["polygon"]["holes"] = [{"circle": {"center": [0.6, 0.3], "radius": 0.2}}]
    message = _refusal(crossing)
    assert "geometry.polygon.holes[0]" in message and "outer boundary" in message
    outside = _hertz()
    outside["geometry"]["polygon"]["holes"] = [{"vertices": [[3, 3], [4, 3], [4, 4]], "edges": ["h", "h", "h"]}]
    assert "outside the body" in _refusal(outside)


def test_facing_the_obstacle_is_decided_on_the_geometry():
    """The half-disk's rim: its ends are tangent to the obstacle (accepted, whatever the mesh);
    turned away from it, or tilted so that part of the arc faces away, it is refused."""
    assert len(prepare(_parse(_hertz())).contact.nodes) > 0
    above = _hertz(obstacle={"point": [0, 3], "normal": [0, 1]})
    message = _refusal(above)
    assert "boundary.rim = contact" in message and "faces away" in message and "arc around (0, 1)" in message
    tilted = _hertz(obstacle={"point": [0, 0], "normal": [0.1736481776669303, -0.984807753012208]})
    message = _refusal(tilted)
    assert "faces away" in message and "between -0.174 and 1" in message


@pytest.mark.parametrize("name", ["hertz.yaml", "flat_punch.yaml"])
def test_the_graded_size_field_is_its_formula_with_exact_distances_near_and_far(name):
    """h(x) = min(size, contact_size + grading · d(x)), d the distance to ΓC's samples (and,
    facing a finite obstacle's ends, min with contact_size / 4 + grading · d_end): the
    nearest-sample search, which stops where h can only be ``size``, gives the brute-force
    values exactly, near ΓC and beyond that reach."""
    import numpy as np

    from contactfem.case import load_case
    from contactfem.discretize.meshing import END_REFINEMENT, _contact_grading, _contact_samples

    case = load_case(CASES / name)
    settings = case.mesh
    samples, ends = _contact_samples(case)
    size = _contact_grading(case)
    vertices = case.geometry.outer.vertices
    low, high = vertices.min(axis=0), vertices.max(axis=0)
    rng = np.random.default_rng(7)
    near = samples[np.linspace(0, len(samples) - 1, 200).astype(int)]
    near = near + rng.normal(scale=2 * settings.contact_size, size=near.shape)
    points = np.concatenate([rng.uniform(low, high, size=(400, 2)), near])

    def distance(to: np.ndarray) -> np.ndarray:
        return np.sqrt(((points[:, None, :] - to[None, :, :]) ** 2).sum(axis=2)).min(axis=1)

    d = distance(samples)
    expected = np.minimum(settings.size, settings.contact_size + settings.grading * d)
    if len(ends):
        expected = np.minimum(expected, settings.contact_size / END_REFINEMENT + settings.grading * distance(ends))
    reach = (settings.size - settings.contact_size) / settings.grading
    assert (d > reach).any() and (d < reach).any()  # both sides of where the search stops
    assert np.array_equal(size(points), expected)
