"""Refusals say what is wrong with the case as given and what to turn, naming the case file.

- A body free to slide under a platen force: the remedies that keep the load (a symmetry
  line, one prescribed component), not only the one that fixes the body in place.
- A body's extent is its outline's (arcs included), not its vertices': a half-disk's top
  split by a vertex is three vertices on one line, and was refused as of extent 0.
- A numerically singular body: the message starts with the case file, like every other.
"""

from __future__ import annotations

import pytest
import yaml
from conftest import make_runner
from test_platen import FORCE, solved, wedge, platen_of

from contactfem.cli import main

CASE_NAME = "told.yaml"


def _write(tmp_path, data: dict, name: str = CASE_NAME):
    path = tmp_path / name
    path.write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
    return path


def _refused(tmp_path, data: dict, *fragments: str, command: str = "solve") -> str:
    path = _write(tmp_path, data)
    args = [command, str(path)] + (["--out", str(tmp_path / "out"), "--quiet"] if command == "solve" else [])
    result = make_runner().invoke(main, args)
    assert result.exit_code == 2, (result.exit_code, result.stderr, result.stdout)
    assert "Traceback" not in result.stderr
    lines = result.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"error: {CASE_NAME}: "), result.stderr
    for fragment in fragments:
        assert fragment in lines[0], f"{fragment!r} not in {lines[0]!r}"
    assert not (tmp_path / "out").exists()
    return lines[0]


# --------------------------------------------------------------------------- a body free to slide


def test_a_body_free_to_slide_under_a_platen_force_is_told_the_remedies_that_keep_the_load(tmp_path):
    """The wedge pressed by a platen force onto a frictionless plane, nothing else holding it
    sideways: the message names the free translation, the straight free parts across it as
    symmetry lines, one prescribed component, and that there are no springs; fixing a part
    in place (both components) comes last, as what changes the problem."""
    line = _refused(tmp_path, wedge({"left": "free", "top": {"platen": {"force": FORCE}}}),
                    "a translation along (1, 0)", "keep the load", "boundary.right or boundary.left: symmetry",
                    "{displacement: [0, null]}", "no springs")
    assert line.index("symmetry line") < line.index("both components")


@pytest.mark.parametrize("remedy", [{"left": "symmetry"}, {"left": {"displacement": [0, None]}}],
                         ids=["symmetry", "one-component"])
def test_the_remedies_named_keep_the_platen_force(remedy):
    """Either remedy the message names solves, and the platen still presses with its force."""
    outcome = solved(wedge({"top": {"platen": {"force": FORCE}}, **remedy}))
    platen = platen_of(outcome)
    assert abs(platen["force"] - FORCE) <= 1e-8 * FORCE
    # The plane carries the platen's vertical part, the remedy its sideways one.
    vertical = FORCE * abs(platen["normal"][1])
    assert abs(float(outcome.solution.contact.nodal_force.sum()) - vertical) <= 1e-8 * FORCE


def test_a_slide_along_an_inclined_obstacle_names_its_direction(tmp_path):
    """An obstacle tilted so that the free translation is along (0.8, 0.6): no part of the
    wedge lies across it, so the message says which direction a symmetry line must hold."""
    data = wedge({"left": "free", "top": {"platen": {"force": FORCE}}})
    data["obstacle"]["normal"] = [0.6, -0.8]
    _refused(tmp_path, data, "a translation along (0.8, 0.6)", "across (0.8, 0.6)", "{displacement: [0, null]}")
