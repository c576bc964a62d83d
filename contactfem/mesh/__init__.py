"""Mesh construction: structured rectangles, Triangle meshes of curved polygons, Gmsh files, refinement."""

from contactfem.mesh.core import Circle, Mesh
from contactfem.mesh.gmsh_io import read_gmsh, write_gmsh
from contactfem.mesh.polygon import Arc, Loop, circle_loop, polygon_problems, triangulate_domain
from contactfem.mesh.quality import check_mesh
from contactfem.mesh.refine import boundary_edges, prolongation, refine_uniform
from contactfem.mesh.structured import structured_rectangle

__all__ = [
    "Arc",
    "Circle",
    "Loop",
    "Mesh",
    "boundary_edges",
    "check_mesh",
    "circle_loop",
    "polygon_problems",
    "prolongation",
    "read_gmsh",
    "refine_uniform",
    "structured_rectangle",
    "triangulate_domain",
    "write_gmsh",
]
