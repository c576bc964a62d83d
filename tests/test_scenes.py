"""Scenes nobody chose (benchmarks/scenes.py), a few of them in the default run: each is
solved through `python -m contactfem solve` and must be certified, the resultant of its
forces within what its certificate implies, or refused in one line; the benchmark runs
hundreds."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))

import scenes  # noqa: E402

#: One of each kind: a half-disk on its rim and one along a load path, a rectangle on a
#: finite table, a star along a load path, a profile under its weight, a profile clamped at
#: one end under a wavy traction over a table, a profile under a platen force, a holed
#: block under a platen force (these last two held along the normal by contact alone).
SEEDS = (0, 12, 5, 6, 9, 14, 20, 30)


def test_a_scene_is_drawn_from_its_seed_alone():
    assert scenes.scene(9) == scenes.scene(9) and scenes.scene(9) != scenes.scene(10)
    kinds = {next(iter(scenes.scene(seed)["geometry"])) for seed in SEEDS}
    assert kinds == {"polygon", "rectangle", "profile"}


@pytest.mark.parametrize("seed", SEEDS)
def test_random_scenes_are_certified(seed, tmp_path):
    record = scenes.run_scene(seed, tmp_path)
    assert record["outcome"] == "certified", record.get("message")
    assert record["relative_precision"] < 1e-6  # these are well conditioned


@pytest.mark.parametrize("seed", (8, 9))
def test_a_scene_solved_again_from_its_mesh_written_by_gmsh_agrees(seed, tmp_path):
    """The scene's own mesh, renumbered, partly clockwise, with unused nodes and reversed
    boundary lines, written by Gmsh in format 4.1 (seed 8) and 2.2 binary (seed 9): the
    same discrete problem, so the same contact force within what the two certificates
    allow (twice their tolerance times the condition estimate, of the force scale)."""
    record = scenes.run_scene(seed, tmp_path, mesh_files=1.0)
    twin = record["mesh_file_twin"]
    assert record["outcome"] == "certified" and twin["agrees"], record.get("message")
    assert twin["written"]["format"] == {8: "4.1", 9: "2.2"}[seed]
    assert twin["written"]["clockwise_triangles"] > 0
    assert twin["contact_force_difference"] <= twin["allowed"]


#: The rough family: a block on a 1 531-point profile (one column of heights) under a
#: pressure, on a finite table, and a half-disk whose 3 049-vertex rough outline is a file,
#: pushed by its top, with the standard method.
ROUGH_SEEDS = (11, 29)


def test_a_rough_scene_is_drawn_from_its_seed_alone():
    first, again = scenes.scene(11, "rough"), scenes.scene(11, "rough")
    assert first == again and first != scenes.scene(12, "rough")
    assert first["_surface"]["kind"] == "profile" and scenes.scene(29, "rough")["_surface"]["kind"] == "outline"
    assert "surface.csv" in first["_files"] and first["geometry"]["profile"]["file"] == "surface.csv"


@pytest.mark.parametrize("seed", ROUGH_SEEDS)
def test_rough_scenes_read_from_files_are_certified_in_many_patches(seed, tmp_path):
    record = scenes.run_scene(seed, tmp_path, family="rough")
    assert record["outcome"] == "certified", record.get("message")
    assert record["active_nodes"] >= 100 and record["contact_patches"] >= 10
    assert (tmp_path / f"rough-scene-{seed}" / record["case"]["geometry"].popitem()[1]["file"]).is_file()
