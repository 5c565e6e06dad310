"""Meshes: reading and checking, cotangent operators, spherical embedding, correspondences.

Pipeline: :func:`load` -> :func:`check` -> :func:`spherical_embedding` -> :class:`Correspondence`
(sampling for the fit, point location for evaluation). Cotangent operators, FEM eigenvalues
and curvature baselines serve as references.

Heavy optional dependencies (meshio, trimesh, libigl) are imported inside the functions that
need them.
"""

from .baselines import (
    Curvatures,
    baseline_curvatures,
    curvature_jitter,
    discrete_curvatures,
)
from .check import MeshSummary, check
from .closest import ClosestPoint
from .correspondence import Correspondence, sample_surface, uniform_barycentric
from .embedding import EmbeddingReport, mobius_centre, spherical_embedding
from .equalise import equalise_areas
from .errors import (
    BoundaryError,
    DegenerateFaceError,
    DisconnectedError,
    DuplicateFaceError,
    EmbeddingError,
    GenusError,
    MeshDefectError,
    MeshError,
    MeshFileError,
    NonManifoldError,
    OrientationError,
    UnreferencedVertexError,
)
from .export import write_mesh, written_field_names
from .foldrepair import FoldRepair
from .heights import NormalHeights, midpoint_subdivision, subdivided_points
from .icosphere import icosphere
from .io import LoadReport, MeshRepairWarning, load
from .operators import (
    corner_normals,
    cotan_laplacian,
    face_angles,
    face_areas,
    face_normals,
    mass_matrix,
    normal_turn,
    signed_volume,
    surface_area,
    vertex_normals,
)
from .spectrum import eigenvalues, laplacian_eigenmodes
from .spherical import (
    SphereLocator,
    area_distortion,
    face_stretch,
    orientation_determinants,
    spherical_triangle_areas,
    uniform_in_spherical_triangles,
)
from .stretch import minimise_stretch

__all__ = [
    # input and checks
    "load", "LoadReport", "MeshRepairWarning", "write_mesh", "written_field_names", "check",
    "MeshSummary", "icosphere",
    # operators
    "face_areas", "face_normals", "face_angles", "vertex_normals", "corner_normals",
    "normal_turn",
    "cotan_laplacian",
    # a surface following the vertex normals
    "NormalHeights", "midpoint_subdivision", "subdivided_points",
    "mass_matrix", "surface_area", "signed_volume",
    # spectrum and baselines
    "laplacian_eigenmodes", "eigenvalues", "baseline_curvatures", "discrete_curvatures",
    "curvature_jitter", "Curvatures",
    # spherical embedding
    "spherical_embedding", "EmbeddingReport", "mobius_centre", "minimise_stretch",
    "equalise_areas", "FoldRepair", "orientation_determinants", "spherical_triangle_areas",
    "uniform_in_spherical_triangles",
    "area_distortion", "face_stretch",
    # correspondence
    "Correspondence", "sample_surface", "uniform_barycentric", "SphereLocator", "ClosestPoint",
    # errors
    "MeshError", "MeshFileError", "MeshDefectError", "DegenerateFaceError", "DuplicateFaceError",
    "UnreferencedVertexError", "NonManifoldError", "BoundaryError", "OrientationError",
    "DisconnectedError", "GenusError", "EmbeddingError",
]
