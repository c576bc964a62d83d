"""The square case of cases/square.yaml solved with GetFEM, for a side-by-side with contactfem.

Runs with Debian's Python (the one that has ``python3-getfem``), not the project's:

    apt-get install -y python3-getfem
    /usr/bin/python3 benchmarks/getfem_square.py 64 128 256

Same discrete problem as contactfem: the unit square on an N x N grid, each cell split by
its lower-left to upper-right diagonal (``diagonal: right``), P1 vector displacement
(FEM_PK(2,1)), plane strain linear elasticity with E = 1e6, nu = 0.3, the left side
clamped (Dirichlet condition with multipliers, see --dirichlet), the traction
(1e4, -1e4 (1 - 1.5 x)) on the top, and frictionless nodal contact of the bottom nodes
with the rigid obstacle y <= 0 (``add_nodal_contact_with_rigid_obstacle_brick``, signed
distance "y", Alart-Curnier augmented Lagrangian with r = E), solved by GetFEM's Newton
with MUMPS. As in contactfem, the corner node (0, 0), whose displacement the clamp
fixes, carries no contact multiplier: the contact region is the bottom edges minus the
one that touches x = 0 (with it, its multiplier is undetermined and the tangent matrix
singular).

Per N, a JSON object on stdout (a list of them), with:
  setup_s          mesh, regions, FEM, integration method and model bricks (no assembly)
  solve_s          md.solve(...): every Newton iteration, each with its assembly and MUMPS solve
  iterations       Newton iterations reported by md.solve; converged
  linear_*         the baseline: the same elasticity without contact, assembled once
                   (linear_assembly_s) and solved once with gf.linsolve_mumps (linear_solve_s)
  contact_force    sum of the bottom nodal reactions (compression > 0), to compare with
                   contactfem's report["contact_force"]["normal"]
  contact_zone     [min x, max x] of the nodes with a nonzero reaction
  peak_rss_gb      the process's peak resident memory (run one N per process for a per-N figure)
GetFEM's and MUMPS' own messages go to stderr so that stdout stays JSON.

--dirichlet: "multipliers" (default) adds a multiplier per clamped dof, assembled once;
"simplification" eliminates the clamped dofs, which GetFEM 5.4 redoes in every Newton
iteration at a cost that grows faster than the system (about 5 s per iteration at
N = 256, against 0.03 s for a reassembly with multipliers): it gives the same answer but
measures that elimination rather than the contact solve.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import subprocess
import sys
import time

import numpy as np

E = 1.0e6
NU = 0.3
LAME_LAMBDA = E * NU / ((1 + NU) * (1 - 2 * NU))
LAME_MU = E / (2 * (1 + NU))
TRACTION = "[1e4, -1e4*(1-1.5*X(1))]"
OBSTACLE = "y"  # signed distance to the obstacle y <= 0, positive outside
LEFT, TOP, BOTTOM = 1, 2, 3


def grid_mesh(gf, n: int):
    """The unit square, n x n cells, each split by its lower-left to upper-right diagonal."""
    x = np.linspace(0.0, 1.0, n + 1)
    xx, yy = np.meshgrid(x, x)
    points = np.vstack([xx.ravel(), yy.ravel()])
    i, j = np.meshgrid(np.arange(n), np.arange(n))
    a = (j * (n + 1) + i).ravel()
    b, c, d = a + 1, a + n + 2, a + n + 1
    triangles = np.hstack([np.vstack([a, b, c]), np.vstack([a, c, d])])
    return gf.Mesh("pt2D", points, triangles)


def set_regions(mesh) -> None:
    faces = mesh.outer_faces()
    normals = mesh.normal_of_faces(faces)
    mesh.set_region(LEFT, faces[:, normals[0] < -0.5])
    mesh.set_region(TOP, faces[:, normals[1] > 0.5])
    bottom = faces[:, normals[1] < -0.5]
    x = mesh.pts()[0]
    keep = [k for k in range(bottom.shape[1]) if (x[mesh.pid_in_faces(bottom[:, k:k + 1])] > 1e-12).all()]
    mesh.set_region(BOTTOM, bottom[:, keep])


def elasticity_model(gf, mim, mfu, dirichlet: str):
    model = gf.Model("real")
    model.add_fem_variable("u", mfu)
    model.add_initialized_data("lambda", [LAME_LAMBDA])
    model.add_initialized_data("mu", [LAME_MU])
    model.add_isotropic_linearized_elasticity_brick(mim, "u", "lambda", "mu")
    model.add_source_term_brick(mim, "u", TRACTION, TOP)
    if dirichlet == "multipliers":
        model.add_Dirichlet_condition_with_multipliers(mim, "u", mfu, LEFT)
    else:
        model.add_Dirichlet_condition_with_simplification("u", LEFT)
    return model


def run(gf, n: int, linear: bool, max_res: float, max_iter: int, dirichlet: str) -> dict:
    peak = lambda: resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20  # noqa: E731
    clock = time.perf_counter()
    mesh = grid_mesh(gf, n)
    set_regions(mesh)
    mfu = gf.MeshFem(mesh, 2)
    mfu.set_fem(gf.Fem("FEM_PK(2,1)"))
    mim = gf.MeshIm(mesh, gf.Integ("IM_TRIANGLE(2)"))
    mesh_s = time.perf_counter() - clock

    model = elasticity_model(gf, mim, mfu, dirichlet)
    contact_dofs = mfu.basic_dof_on_region(BOTTOM)
    n_contact = len(contact_dofs) // 2
    model.add_variable("lambda_n", n_contact)
    model.add_initialized_data("r", [E])
    model.add_nodal_contact_with_rigid_obstacle_brick(mim, "u", "lambda_n", "r", BOTTOM, OBSTACLE, 1)
    setup_s = time.perf_counter() - clock

    clock = time.perf_counter()
    iterations, converged = model.solve("max_res", max_res, "max_iter", max_iter, "lsolver", "mumps")
    solve_s = time.perf_counter() - clock
    contact_peak = peak()

    multiplier = np.asarray(model.variable("lambda_n"))
    node_x = mfu.basic_dof_nodes(contact_dofs[::2])[0]
    force = -multiplier  # the brick's multiplier is the nodal force on the body: < 0 in compression
    pressed = node_x[force > 1e-10 * max(abs(force).max(), 1e-300)]
    record = {
        "tool": "getfem",
        "N": n,
        "dirichlet": dirichlet,
        "nodes": int(mesh.nbpts()),
        "triangles": int(mesh.nbcvs()),
        "unknowns": int(mfu.nbdof() - 2 * (n + 1)),
        "model_dofs": int(model.nbdof()),
        "contact_nodes": int(n_contact),
        "mesh_s": mesh_s,
        "setup_s": setup_s,
        "solve_s": solve_s,
        "iterations": int(iterations),
        "solve_per_iteration_s": solve_s / max(int(iterations), 1),
        "converged": bool(converged),
        "contact_force": float(force.sum()),
        "contact_zone": [float(pressed.min()), float(pressed.max())] if len(pressed) else None,
        "active_nodes": int(len(pressed)),
        "peak_rss_gb": contact_peak,
    }
    del model

    if linear:
        clock = time.perf_counter()
        model = elasticity_model(gf, mim, mfu, dirichlet)
        record["linear_setup_s"] = time.perf_counter() - clock
        clock = time.perf_counter()
        model.assembly("build_all")
        matrix, rhs = model.tangent_matrix(), model.rhs()
        record["linear_assembly_s"] = time.perf_counter() - clock
        clock = time.perf_counter()
        solution = gf.linsolve_mumps(matrix, rhs)
        record["linear_solve_s"] = time.perf_counter() - clock
        model.to_variables(solution)
        # max |u| of the linear solution: contactfem's baseline_solution_max, if the problems agree
        record["linear_solution_max"] = float(np.abs(np.asarray(model.variable("u"))).max())
        record["linear_model_dofs"] = int(model.nbdof())
        record["peak_rss_gb_with_linear"] = peak()
    record["total_s"] = setup_s + solve_s
    return record


def versions() -> dict:
    info = {"python": platform.python_version(), "numpy": np.__version__}
    for package in ("python3-getfem", "libmumps-seq-5.5"):
        try:
            info[package] = subprocess.run(
                ["dpkg-query", "-W", "-f", "${Version}", package],
                capture_output=True, text=True, check=True).stdout.strip()
        except (OSError, subprocess.CalledProcessError):
            info[package] = None
    return info


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("sizes", nargs="+", type=int, help="divisions per side")
    parser.add_argument("--no-linear", action="store_true", help="skip the linear-solve baseline")
    parser.add_argument("--max-res", type=float, default=1e-9)
    parser.add_argument("--max-iter", type=int, default=50)
    parser.add_argument("--dirichlet", choices=("multipliers", "simplification"), default="multipliers",
                        help="how the clamp is imposed (default %(default)s)")
    args = parser.parse_args()

    # GetFEM and MUMPS print from C++; keep the real stdout for the JSON alone.
    out = os.fdopen(os.dup(1), "w")
    sys.stdout.flush()
    os.dup2(2, 1)
    try:
        import getfem as gf
    except ImportError as error:
        out.write(json.dumps({"error": f"cannot import getfem with {sys.executable}: {error}"}) + "\n")
        sys.exit(2)
    gf.util_trace_level(0)
    gf.util_warning_level(1)

    info = versions()
    records = []
    for n in args.sizes:
        record = run(gf, n, not args.no_linear, args.max_res, args.max_iter, args.dirichlet)
        record["versions"] = info
        records.append(record)
        print(f"getfem N={n}: {record['iterations']} Newton, solve {record['solve_s']:.2f} s, "
              f"force {record['contact_force']:.6f}", file=sys.stderr, flush=True)
    out.write(json.dumps(records, indent=2) + "\n")
    out.flush()


if __name__ == "__main__":
    main()
