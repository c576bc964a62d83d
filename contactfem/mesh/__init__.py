"""Mesh construction: structured rectangles, Triangle meshes of curved polygons, Gmsh files, refinement.

The names are imported on first use, so that ``contactfem.mesh.core`` and
``contactfem.mesh.topology`` (what the numerical core needs) load without the meshing
libraries (Triangle, meshio).
"""

from importlib import import_module

_WHERE = {
    "Circle": "core", "Mesh": "core", "coordinate_span": "core",
    "read_gmsh": "gmsh_io", "write_gmsh": "gmsh_io",
    "Arc": "polygon", "Loop": "polygon", "circle_loop": "polygon", "polygon_problems": "polygon",
    "triangulate_domain": "polygon",
    "check_mesh": "quality",
    "boundary_edges": "refine", "prolongation": "refine", "refine_uniform": "refine",
    "structured_rectangle": "structured",
    "interpolate_p1": "transfer",
}

__all__ = sorted(_WHERE)


def __getattr__(name: str):
    if name not in _WHERE:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(import_module(f"{__name__}.{_WHERE[name]}"), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return __all__
