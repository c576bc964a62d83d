"""Scenes nobody chose: random bodies, obstacles and loads through ``contactfem solve``.

Usage: python benchmarks/scenes.py [--count 200] [--seed 0] [--jobs 2] [--more] [--backend NAME]
                                  [--mesh-files | --all-mesh-files] [--family mixed|rough|indenter] [--out FILE.json]

Each scene is drawn from its seed (the same seed, the same case):

- bodies: rectangles of aspect 1/200 to 20, a third of them with a circular hole; star
  polygons of 6 to 40 vertices (graded onto their base or not); half-disks; profiles that
  are sums of sines, of 100 to 2 000 points; sizes from 1e-3 to 1e3;
- material: E from 1e-2 to 1e11, ν from 0 to 0.4999, plane strain or stress;
- obstacle: a line tilted by up to some 30°, through the body's farthest point along its
  normal, touching, short of it or overlapping; a fifth of the rectangles and profiles
  on a finite table instead;
- supports and loads: a pushed or sheared top, a pressure or a platen force with a
  symmetry side (a body that contact alone holds along the normal), a platen driven by
  displacement, its weight, a cantilever under a wavy traction, a traction that lifts;
- either method; 15% as load paths of 2 to 6 steps.

``--family rough`` draws rough surfaces read from files instead, as users bring measured
ones (``benchmarks/rough.py``'s spectral synthesis, Hurst exponent 0.3 to 0.9, seeded per
scene): two thirds are blocks on a profile of 500 to 20 000 points, 1e-5 to 1e-2 of their
length high, in a CSV of x, h or of heights alone with the spacing in the case; a third
are half-disks whose rim is a closed outline of 500 to 8 000 vertices in a file (x, y,
part), roughened radially by 1e-4 to 1e-2 of the radius. The load presses the surface in
by 5% to twice its relief; material, method, supports, loads, tables and load paths are
drawn as above. It writes benchmarks/results/scenes_rough.json.

``--family indenter`` presses rigid obstacles of other shapes into a block (width 1e-3 to
1e3, aspect 0.2 to 5, clamped base, the top its contact part, meshed uniformly or graded
onto it): a cylinder of radius 0.05 to 50 widths, a wedge of 0.3 to 30 degrees, a flat
punch with chamfered corners, or a rigid wavy profile, off centre and tilted by up to 10
degrees; moved by a prescribed advance, pushed by a force sized for a contact zone of 2%
to 30% of the width, or placed overlapping the block; either method, 15% as load paths.
It writes benchmarks/results/scenes_indenter.json.

A scene's contact parts are the edges that face the obstacle (a star's base), as a user
would mark them. Each solve runs in its own process (``python -m contactfem solve``) and
counts as:

- ``certified``: exit 0, report.json's certificate passed, and the resultant of all forces
  on the body within what the certificate implies: a sum over the unknowns of nodal
  residuals each within max(tolerance, round-off bound) of the force scale;
- ``refused``: exit 2 with one line (a body left free to slide, a table beside the body);
- ``failed``: anything else (exit 1, a traceback, a crash, exit 0 not certified, more than
  one line) — the figure that must stay 0.

A certified scene whose body is straight-edged is then solved again from its own mesh
written by Gmsh (its Python API, from the test extra) the way meshers and converters
leave them (``--mesh-files``, a fifth of the scenes; all with ``--all-mesh-files``): nodes
renumbered at random, a few unused nodes, some or all triangles clockwise, boundary lines
reversed, the 2.2 or 4.1 format in ASCII or binary. The twin must be certified too, with the contact force of the
original within what the two certificates allow: twice their tolerance (or round-off
bound, whichever is larger) times the condition estimate, of the force scale.

``--more`` also runs one of ``compare``, ``converge --levels 2`` or ``adapt`` on each
certified scene, which must exit 0. ``--backend`` solves every scene with that sparse
solver (``solver.backend``) instead of the fastest installed. Writes JSON (per scene: seed, case, outcome, seconds,
Newton steps, active nodes) and prints the counts; exits 1 if any scene failed.
"""

from __future__ import annotations

import argparse
import json
import math
import random
import subprocess
import sys
import tempfile
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
import yaml

ROOT = Path(__file__).resolve().parents[1]
#: The scene generators: ``mixed`` bodies (the default), ``rough`` surfaces, rigid ``indenter``s.
FAMILIES = ("mixed", "rough", "indenter")
MODES = ("push", "push", "pressure", "platen", "weight", "cantilever", "shear", "lift", "platen_displacement")


def _log_uniform(rng: random.Random, low: float, high: float) -> float:
    return 10 ** rng.uniform(math.log10(low), math.log10(high))


def _material_and_method(rng: random.Random, title: str) -> tuple[float, float, dict]:
    """A scene's Young's modulus, strain scale and case mapping so far (material, method)."""
    young = _log_uniform(rng, 1e-2, 1e11)
    strain = _log_uniform(rng, 1e-7, 3e-2)
    data: dict = {
        "title": title,
        "material": {"E": young, "nu": rng.choice([0.0, 0.3, rng.uniform(0, 0.49), 0.4999]),
                     "plane": rng.choice(["strain", "stress"])},
        "solver": {"method": rng.choice(["positive", "standard"])},
    }
    return young, strain, data


def scene(seed: int, family: str = "mixed") -> dict:
    """The case (as a YAML mapping) of scene ``seed`` of ``family`` (see :data:`FAMILIES`).

    A case that reads data files carries their text under ``_files`` (name: text), which
    :func:`run_scene` writes beside the case and leaves out of the record."""
    if family == "rough":
        return rough_scene(seed)
    if family == "indenter":
        return indenter_scene(seed)
    rng = random.Random(seed)
    young, strain, data = _material_and_method(rng, f"scene {seed}")
    size = _log_uniform(rng, 1e-3, 1e3)
    tilt = rng.choice([0.0, 0.0, rng.gauss(0, 3), rng.gauss(0, 10)])
    kind = rng.choice(["rectangle", "rectangle", "star", "profile", "half-disk"])
    if kind == "half-disk":
        tilt = 0.0  # its quarter arcs end tangent to a level obstacle and face away from a tilted one
    angle = math.radians(tilt)
    normal = (math.sin(angle), -math.cos(angle))
    side = None
    if kind == "rectangle":
        length, height = size, size / _log_uniform(rng, 0.05, 200)
        nx = rng.randint(4, 200)
        ny = max(1, min(200, round(nx * height / length)))
        data["geometry"] = {"rectangle": {"lower": [0, 0], "upper": [length, height]}}
        data["mesh"] = {"divisions": [nx, ny]}
        if rng.random() < 0.3:
            radius = 0.25 * min(length, height)
            data["geometry"] = {"polygon": {
                "vertices": [[0, 0], [length, 0], [length, height], [0, height]],
                "edges": ["bottom", "right", "top", "left"],
                "holes": [{"circle": {"center": [length / 2, height / 2], "radius": radius}, "name": "hole"}]}}
            data["mesh"] = {"size": min(length, height) / rng.choice([8, 16, 32])}
        base, top, side, width = "bottom", "top", "left", length
        outline = [(0.0, 0.0), (length, 0.0)]
    elif kind == "star":
        corners = rng.randint(6, 40)
        points = []
        for i in range(corners):
            at = -math.pi / 2 + 2 * math.pi * i / corners
            radius = size * rng.uniform(0.6, 1.0)
            points.append([radius * math.cos(at), size + radius * math.sin(at)])
        lowest = min(p[1] for p in points)
        points = [[x, y - lowest] for x, y in points]
        edges = []
        for i in range(corners):
            (x0, y0), (x1, y1) = points[i], points[(i + 1) % corners]
            outward = (y1 - y0, -(x1 - x0))  # counter-clockwise loop
            facing = (outward[0] * normal[0] + outward[1] * normal[1]) / math.hypot(*outward)
            edges.append("base" if facing > 0.3 else "rim")
        data["geometry"] = {"polygon": {"vertices": points, "edges": edges}}
        data["mesh"] = {"size": size / rng.choice([5, 10, 20])}
        if rng.random() < 0.5:
            data["mesh"].update(contact_size=size / 200, grading=0.3)
        base, top, width, height = "base", "rim", 2 * size, 2 * size
        outline = [tuple(p) for p in points]
    elif kind == "half-disk":
        data["geometry"] = {"polygon": {"vertices": [[-size, size], [0, 0], [size, size]], "edges": [
            {"name": "base", "arc": {"center": [0, size], "direction": "ccw"}},
            {"name": "base", "arc": {"center": [0, size], "direction": "ccw"}}, "top"]}}
        data["mesh"] = {"size": size / 10, "contact_size": size / rng.choice([50, 200, 1000]), "grading": 0.2}
        base, top, width, height = "base", "top", 2 * size, size
        outline = [(0.0, 0.0)]
    else:
        length = size
        amplitude = length * _log_uniform(rng, 1e-5, 2e-2)
        terms = " + ".join(
            f"{amplitude / (j + 1):.6g}*sin({2 * math.pi * (j + 1) * rng.randint(1, 8) / length:.6g}*x"
            f" + {rng.uniform(0, 6.28):.4g})" for j in range(rng.randint(1, 4)))
        count = rng.choice([100, 400, 2000])
        x = np.linspace(0, length, count)
        heights = eval(terms, {"sin": np.sin, "x": x})  # the generator's own expression
        depth = length * rng.uniform(0.1, 1.0)
        data["geometry"] = {"profile": {"expression": terms, "x": [0, length], "points": count,
                                        "depth": depth + float(heights.max())}}
        data["mesh"] = {"size": depth / rng.choice([5, 10, 20])}
        base, top, side, width, height = "base", "top", "left", length, depth
        outline = list(zip(x.tolist(), heights.tolist()))
    _supports_loads_and_obstacle(rng, data, young * strain, strain, kind, base, top, side, width, height, outline,
                                 normal)
    return data


def indenter_scene(seed: int) -> dict:
    """Scene ``seed`` of the indenter family: a rigid shape pressed into a clamped block (see
    the module's docstring)."""
    rng = random.Random(seed)
    young, strain, data = _material_and_method(rng, f"indenter scene {seed}")
    nu = data["material"]["nu"]
    modulus = young / (1 - nu**2) if data["material"]["plane"] == "strain" else young
    width = _log_uniform(rng, 1e-3, 1e3)
    height = width * _log_uniform(rng, 0.2, 5)
    half = width / 2
    data["geometry"] = {"polygon": {"vertices": [[-half, -height], [half, -height], [half, 0], [-half, 0]],
                                    "edges": ["base", "right", "surface", "left"]}}
    contact = width / rng.choice([100, 400, 1600])
    data["mesh"] = ({"size": contact} if rng.random() < 0.3 else
                    {"size": min(width, height) / rng.choice([4, 8, 16]), "contact_size": contact})
    data["boundary"] = {"base": "clamped", "left": rng.choice(["free", "free", "symmetry"]), "right": "free",
                        "surface": "contact"}
    zone = width * _log_uniform(rng, 0.02, 0.3)  # the contact half-width aimed at
    centre = rng.uniform(-0.3, 0.3) * width
    tilt = math.radians(rng.choice([0.0, 0.0, rng.uniform(-10, 10)]))
    direction = [round(math.sin(tilt), 12), round(-math.cos(tilt), 12)]
    shape = rng.choice(["circle", "circle", "wedge", "punch", "profile"])
    if shape == "circle":
        radius = width * _log_uniform(rng, 0.05, 50)
        zone = min(zone, 0.5 * radius)
        force, advance = math.pi * modulus * zone**2 / (4 * radius), zone**2 / radius
        obstacle: dict = {"circle": {"center": [centre, radius], "radius": radius}}
    elif shape == "wedge":
        slope = math.tan(math.radians(_log_uniform(rng, 0.3, 30)))
        force, advance = zone * modulus * slope, zone * slope
        obstacle = {"polyline": [[centre + width, width * slope], [centre, 0.0], [centre - width, width * slope]]}
    elif shape == "punch":
        flat, chamfer = zone, zone * rng.uniform(0.05, 0.5)
        force, advance = 2 * flat * modulus * strain, strain * height
        obstacle = {"polyline": [[centre + flat + chamfer, chamfer], [centre + flat, 0.0],
                                 [centre - flat, 0.0], [centre - flat - chamfer, chamfer]]}
    else:
        relief = zone * _log_uniform(rng, 1e-4, 1e-1)
        terms = " + ".join(f"{relief / (j + 1):.6g}*sin({2 * math.pi * rng.randint(1, 12) / width:.6g}*x"
                           f" + {rng.uniform(0, 6.28):.4g})" for j in range(rng.randint(1, 3)))
        # Walked from right to left so that the obstacle, on the walk's right, lies above.
        obstacle = {"profile": {"expression": f"{relief:.6g} - ({terms})", "x": [-width, width],
                                "points": rng.choice([50, 500, 5000]), "origin": [centre, 0.0], "direction": [-1, 0]}}
        force, advance = 2 * width * modulus * strain, 2 * relief + strain * height
    mode = rng.choice(["advance", "advance", "force", "placed"])
    if mode == "advance":
        obstacle["motion"] = {"direction": direction, "displacement": advance}
    elif mode == "force":
        obstacle["motion"] = {"direction": direction, "force": force}
    elif "circle" in obstacle:  # placed overlapping the block: an imposed indentation
        obstacle["circle"]["center"][1] -= advance
    elif "polyline" in obstacle:
        obstacle["polyline"] = [[x, y - advance] for x, y in obstacle["polyline"]]
    else:
        obstacle["profile"]["origin"][1] -= advance
    data["obstacle"] = obstacle
    if rng.random() < 0.15:
        data["load_path"] = {"steps": rng.randint(2, 6)}
    data["output"] = {"files": ["json"]}
    return data


def rough_scene(seed: int) -> dict:
    """Scene ``seed`` of the rough family: a self-affine surface (Hurst exponent 0.3 to 0.9)
    read from a file, as users bring measured ones (see the module's docstring)."""
    from rough import outline_text, profile_text, rim_outline, self_affine_profile

    rng = random.Random(seed)
    young, strain, data = _material_and_method(rng, f"rough scene {seed}")
    size = _log_uniform(rng, 1e-3, 1e3)
    hurst = rng.uniform(0.3, 0.9)
    phases = rng.randrange(2**32)
    if rng.random() < 2 / 3:  # a block on a profile
        points = int(_log_uniform(rng, 500, 20_000))
        relief = size * _log_uniform(rng, 1e-5, 1e-2)
        x, h = self_affine_profile(points, hurst=hurst, height=relief, length=size, seed=phases)
        tilt = rng.choice([0.0, 0.0, rng.gauss(0, 3)])
        depth = size * rng.uniform(0.1, 1.0)
        profile: dict = {"file": "surface.csv", "depth": relief + depth}
        if rng.random() < 0.5:  # one column of heights, the spacing given
            profile["spacing"] = size / (points - 1)
            text = profile_text(None, h)
        else:
            text = profile_text(x, h)
        data["geometry"] = {"profile": profile}
        data["mesh"] = {"size": depth / rng.choice([5, 10, 20])}
        kind, base, top, side, width, height = "profile", "base", "top", "left", size, depth
        outline = list(zip(x.tolist(), h.tolist()))
    else:  # a half-disk whose rim is a closed outline from a file (no graph h(x))
        points = int(_log_uniform(rng, 500, 8_000))
        relief = _log_uniform(rng, 1e-4, 1e-2)  # of the radius
        vertices, parts = rim_outline(points, phases, hurst=hurst, height=relief)
        vertices = vertices * size
        tilt = 0.0
        data["geometry"] = {"polygon": {"file": "outline.csv"}}
        data["mesh"] = {"size": size / rng.choice([5, 10, 20])}
        text = outline_text(vertices, parts)
        kind, base, top, side, width, height = "outline", "rim", "top", None, 2 * size, size
        outline = [tuple(p) for p in vertices.tolist()]
    # The load presses the surface in by a fraction of its relief to twice it: from its
    # highest asperities alone to most of it (the material's own strain scale is not used).
    absolute_relief = relief if kind == "profile" else relief * size
    strain = min(3e-2, absolute_relief / height * _log_uniform(rng, 0.05, 2.0))
    angle = math.radians(tilt)
    normal = (math.sin(angle), -math.cos(angle))
    _supports_loads_and_obstacle(rng, data, young * strain, strain, kind, base, top, side, width, height, outline,
                                 normal)
    data["_files"] = {next(iter(data["geometry"].values()))["file"]: text}
    data["_surface"] = {"kind": kind, "points": points, "hurst": hurst, "relief": relief, "phases": phases}
    return data


def _supports_loads_and_obstacle(rng: random.Random, data: dict, pressure: float, strain: float, kind: str,
                                 base: str, top: str, side: str | None, width: float, height: float,
                                 outline: list[tuple[float, float]], normal: tuple[float, float]) -> None:
    """Draw the scene's supports and load (:data:`MODES`), its obstacle (through the point of
    ``outline`` farthest along ``normal``, or a table along it) and its load path, into
    ``data``; ``side``: a straight side that a symmetry condition may hold (None: none)."""
    mode = rng.choice(MODES)
    if mode in ("pressure", "platen", "platen_displacement", "weight") and side is None:
        mode = "push"  # no straight side to hold it along the obstacle: contact alone cannot
    boundary: dict = {base: "contact"}
    if mode == "push":
        boundary[top] = {"displacement": [rng.choice([0, strain * height * rng.uniform(-1, 1)]), -strain * height]}
    elif mode == "shear":
        boundary[top] = {"displacement": [strain * height, -strain * height * rng.uniform(0, 1)]}
    elif mode == "pressure":
        boundary[top] = {"pressure": pressure}
        if side:
            boundary[side] = "symmetry"
    elif mode == "platen":
        boundary[top] = {"platen": {"force": pressure * width}}
        if side:
            boundary[side] = "symmetry"
    elif mode == "platen_displacement":
        boundary[top] = {"platen": {"displacement": strain * height}}
        if side:
            boundary[side] = "symmetry"
    elif mode == "weight":
        data["body_force"] = [0, -pressure / height]
        boundary[side] = "symmetry"
    elif mode == "lift":
        if side:
            boundary[side] = "clamped"
            boundary[top] = {"traction": [0, f"{pressure}*cos(2*3.14159*x/{width})"]}
        else:
            boundary[top] = {"displacement": [0, strain * height]}
    else:  # cantilever
        if side:
            boundary[side] = "clamped"
            boundary[top] = {"traction": [0, f"{-pressure}*sin({rng.randint(1, 6)}*3.14159*x/{width})"]}
        else:
            boundary[top] = {"displacement": [0, -strain * height]}
    data["boundary"] = boundary

    offset = rng.choice([0.0, 0.0, -1e-3, 1e-3, -1e-2]) * height * strain * 100
    far = max(outline, key=lambda p: p[0] * normal[0] + p[1] * normal[1])
    point = [far[0] + offset * normal[0], far[1] + offset * normal[1]]
    data["obstacle"] = {"point": point, "normal": [round(normal[0], 12), round(normal[1], 12)]}
    if rng.random() < 0.2 and kind in ("rectangle", "profile"):
        # A table along the obstacle's line; the walk keeps the obstacle on its right.
        along = (-normal[1], normal[0])
        spans = [(p[0] - point[0]) * along[0] + (p[1] - point[1]) * along[1] for p in outline]
        low, high = min(spans), max(spans)
        start = low + rng.uniform(-0.2, 0.5) * (high - low)
        end = max(start, low) + rng.uniform(0.3, 1.2) * (high - low)
        ends = [[point[0] + t * along[0], point[1] + t * along[1]] for t in (start, end)]
        walk = (ends[1][0] - ends[0][0], ends[1][1] - ends[0][1])
        right = (walk[1], -walk[0])
        if right[0] * normal[0] + right[1] * normal[1] < 0:
            ends.reverse()
        data["obstacle"] = {"segment": ends}
    if rng.random() < 0.15:
        data["load_path"] = {"steps": rng.randint(2, 6)}
    data["output"] = {"files": ["json"]}


def _contactfem(*args: object, timeout: float = 900) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "contactfem", *map(str, args)], capture_output=True, text=True,
                          timeout=timeout)


_GMSH = threading.Lock()  # the gmsh API keeps one model per process
# One compare, converge or adapt at a time: each may use most of the machine's memory (its
# size guard allows it all), and two of them beside each other were killed by the kernel.
_ONE_STUDY = threading.Lock()


def write_mesh_twin(case_path: Path, path: Path, rng: random.Random) -> dict:
    """The mesh ``case_path`` is solved on, written to ``path`` by Gmsh itself (its API,
    discrete entities) in a random encoding (see the module's docstring); what was chosen."""
    import gmsh

    from contactfem.case import load_case
    from contactfem.discretize.meshing import build_mesh

    mesh = build_mesh(load_case(case_path))
    unused = rng.randint(0, 3)
    tags = np.random.default_rng(rng.randrange(2**32)).permutation(mesh.n_points + unused) + 1
    triangles = tags[mesh.triangles]
    flipped = np.random.default_rng(rng.randrange(2**32)).random(len(triangles)) < rng.choice([0.0, 0.5, 1.0])
    triangles[flipped] = triangles[flipped][:, ::-1]
    version, binary = rng.choice(["2.2", "4.1"]), rng.random() < 0.5
    coordinates = np.column_stack([mesh.points, np.zeros(mesh.n_points)])
    with _GMSH:
        gmsh.initialize(["-noenv"], readConfigFiles=False, interruptible=False)  # off the main thread
        try:
            gmsh.option.setNumber("General.Terminal", 0)
            gmsh.model.add("twin")
            surface = gmsh.model.addDiscreteEntity(2)
            gmsh.model.mesh.addNodes(2, surface, tags[:mesh.n_points].tolist(), coordinates.ravel().tolist())
            gmsh.model.mesh.addElementsByType(surface, 2, [], triangles.ravel().tolist())
            if unused:  # geometry points that no element uses
                point = gmsh.model.addDiscreteEntity(0)
                spare = np.tile(mesh.points.min(axis=0) - 1.0, (unused, 1))
                gmsh.model.mesh.addNodes(0, point, tags[mesh.n_points:].tolist(),
                                         np.column_stack([spare, np.zeros(unused)]).ravel().tolist())
            for name in mesh.part_names:
                lines = tags[mesh.edges_of(name)]
                curve = gmsh.model.addDiscreteEntity(1)
                gmsh.model.mesh.addElementsByType(curve, 1, [], (lines[:, ::-1] if rng.random() < 0.5 else lines)
                                                  .ravel().tolist())
                gmsh.model.addPhysicalGroup(1, [curve], name=name)
            gmsh.model.addPhysicalGroup(2, [surface], name="body")
            gmsh.option.setNumber("Mesh.MshFileVersion", float(version))
            gmsh.option.setNumber("Mesh.Binary", int(binary))
            gmsh.write(str(path))
        finally:
            gmsh.finalize()
    return {"format": version, "binary": binary, "unused_nodes": unused, "clockwise_triangles": int(flipped.sum())}


def _twin_of(record: dict, directory: Path, rng: random.Random) -> dict:
    """Solve the scene again from its mesh as a file; the twin's record, compared."""
    case = json.loads(json.dumps(record["case"]))
    case.pop("mesh", None)
    case["geometry"] = {"mesh_file": "mesh.msh"}
    twin_dir = directory / "twin"
    twin_dir.mkdir(exist_ok=True)
    written = write_mesh_twin(directory / "case.yaml", twin_dir / "mesh.msh", rng)
    path = twin_dir / "case.yaml"
    path.write_text(yaml.safe_dump(case, sort_keys=False), encoding="utf-8")
    done = _contactfem("solve", path, "--out", twin_dir / "out", "--quiet", "--overwrite")
    twin = {"written": written, "exit_code": done.returncode}
    if done.returncode != 0:
        return twin | {"agrees": False, "message": done.stderr.strip()[-1000:]}
    report = json.loads((twin_dir / "out" / "report.json").read_text(encoding="utf-8"))
    original = json.loads((directory / "out" / "report.json").read_text(encoding="utf-8"))
    certified = report["solver"]["status"] == "converged" and report["solver"]["certificate"]["passed"]
    difference = math.dist(report["contact_force"]["vector"], original["contact_force"]["vector"])
    scales = [r["solver"]["certificate"]["scales"] for r in (original, report)]
    allowed = 2 * max(max(c["solver_tolerance"], c["roundoff"]) * c["condition_estimate"] * c["force"] for c in scales)
    twin.update(agrees=certified and difference <= allowed, contact_force_difference=difference, allowed=allowed,
                active_nodes=report["contact_zone"]["active_nodes"])
    if not twin["agrees"]:
        twin["message"] = (f"the mesh file's twin {'is' if certified else 'is not'} certified, its contact force "
                           f"{difference:.3g} from the original's against {allowed:.3g} allowed")
    return twin


def run_scene(seed: int, workdir: Path, more: bool = False, backend: str | None = None,
              mesh_files: float = 0.0, family: str = "mixed") -> dict:
    """Solve scene ``seed`` of ``family`` in ``workdir`` (with ``backend``, if given) and
    classify the outcome."""
    case = scene(seed, family)
    files, surface = case.pop("_files", {}), case.pop("_surface", None)
    if backend is not None:
        case["solver"]["backend"] = backend
    directory = workdir / f"{family}-scene-{seed}"
    directory.mkdir(parents=True, exist_ok=True)
    for name, text in files.items():
        (directory / name).write_text(text, encoding="utf-8")
    path = directory / "case.yaml"
    path.write_text(yaml.safe_dump(case, sort_keys=False), encoding="utf-8")
    started = time.perf_counter()
    try:
        done = _contactfem("solve", path, "--out", directory / "out", "--quiet", "--overwrite")
        code, stderr = done.returncode, done.stderr
    except subprocess.TimeoutExpired:
        code, stderr = "timeout", ""
    record: dict = {"seed": seed, "case": case, "exit_code": code, "seconds": time.perf_counter() - started}
    if surface is not None:
        record["surface"] = surface
    lines = [line for line in stderr.strip().splitlines() if line.strip()]
    if code == 0:
        report = json.loads((directory / "out" / "report.json").read_text(encoding="utf-8"))
        solver = report["solver"]
        scales = solver["certificate"]["scales"]
        resultant = math.hypot(*report["boundary_forces"]["total"]["force"])
        bound = report["unknowns"]["displacement"] * max(scales["solver_tolerance"], scales["roundoff"]) * scales["force"]
        record.update(newton_steps=solver["iterations"], active_nodes=report["contact_zone"]["active_nodes"],
                      contact_patches=len(report["contact_zone"]["intervals"]),
                      contact_nodes=report["contact_zone"]["contact_nodes"],
                      balance=report["boundary_forces"]["total"]["relative_force_residual"],
                      relative_precision=scales["relative_precision"])
        if solver["status"] == "converged" and solver["certificate"]["passed"] and resultant <= bound:
            record["outcome"] = "certified"
        else:
            record.update(outcome="failed", message=f"exit 0 with status {solver['status']}, resultant "
                                                    f"{resultant:.2e} against its bound {bound:.2e}")
    elif code == 2 and len(lines) == 1 and "Traceback" not in stderr:
        record.update(outcome="refused", message=lines[0])
    else:
        record.update(outcome="failed", message=stderr.strip()[-1000:])
    polygon = case["geometry"].get("polygon", {})
    # A mesh file holds straight edges only: no circular hole, no arc.
    straight = not polygon.get("holes") and not any(isinstance(e, dict) and "arc" in e for e in polygon.get("edges", []))
    twin_rng = random.Random(seed + 11)
    if record["outcome"] == "certified" and straight and twin_rng.random() < mesh_files:
        record["mesh_file_twin"] = _twin_of(record, directory, twin_rng)
        if not record["mesh_file_twin"]["agrees"]:
            record.update(outcome="failed", message=record["mesh_file_twin"]["message"])
    if more and record["outcome"] == "certified":
        command = random.Random(seed + 7).choice(
            [["compare"], ["converge", "--levels", "2"], ["adapt", "--max-unknowns", "20000", "--max-seconds", "60"]])
        with _ONE_STUDY:
            other = _contactfem(*command, path, "--out", directory / command[0], "--quiet", "--overwrite")
        record["command"] = {"name": command[0], "exit_code": other.returncode}
        if other.returncode != 0:
            record.update(outcome="failed", message=f"{command[0]}: {other.stderr.strip()[-1000:]}")
    return record


def run(count: int, seed: int = 0, jobs: int = 2, more: bool = False, progress=None,
        backend: str | None = None, mesh_files: float = 0.0, family: str = "mixed") -> dict:
    with tempfile.TemporaryDirectory(prefix="contactfem-scenes-") as workdir, ThreadPoolExecutor(jobs) as pool:
        records = []
        for record in pool.map(lambda s: run_scene(s, Path(workdir), more, backend, mesh_files, family),
                               range(seed, seed + count)):
            records.append(record)
            if progress is not None:
                progress(f"scene {record['seed']}: {record['outcome']} ({record['seconds']:.1f} s)"
                         + (f" {record['message'][:160]}" if record["outcome"] != "certified" else ""))
    counts = {outcome: sum(r["outcome"] == outcome for r in records) for outcome in ("certified", "refused", "failed")}
    return {"benchmark": "scenes", "family": family, "command": " ".join(sys.argv), "count": count, "first_seed": seed,
            "more": more, "backend": backend or "auto", "mesh_files": mesh_files, "counts": counts, "scenes": records}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--count", type=int, default=200)
    parser.add_argument("--seed", type=int, default=0, help="the first scene's seed")
    parser.add_argument("--jobs", type=int, default=2, help="scenes solved at once")
    parser.add_argument("--more", action="store_true", help="also compare, converge or adapt each certified scene")
    parser.add_argument("--backend", help="the sparse solver of every scene (default: the case's, auto)")
    parser.add_argument("--mesh-files", action="store_const", const=0.2, default=0.0,
                        help="solve a fifth of the certified scenes again from their mesh as a Gmsh file")
    parser.add_argument("--all-mesh-files", dest="mesh_files", action="store_const", const=1.0,
                        help="solve every certified straight-edged scene again from its mesh as a Gmsh file")
    parser.add_argument("--family", choices=FAMILIES, default="mixed",
                        help="the mixed bodies (default), rough surfaces read from files or rigid indenters")
    parser.add_argument("--out", type=Path, help="default: benchmarks/results/scenes.json, or scenes_rough.json")
    args = parser.parse_args()
    if args.out is None:
        args.out = ROOT / "benchmarks" / "results" / ("scenes.json" if args.family == "mixed" else
                                                      f"scenes_{args.family}.json")
    results = run(args.count, args.seed, args.jobs, args.more, progress=lambda line: print(line, flush=True),
                  backend=args.backend, mesh_files=args.mesh_files, family=args.family)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(results, indent=1, default=float) + "\n", encoding="utf-8")
    counts = results["counts"]
    print(f"{args.count} scenes: {counts['certified']} certified, {counts['refused']} refused, {counts['failed']} failed")
    sys.exit(1 if counts["failed"] else 0)


if __name__ == "__main__":
    main()
