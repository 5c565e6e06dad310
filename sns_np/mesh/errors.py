"""Specific mesh errors.

All of them subclass :class:`sns_np.errors.MeshError` (itself a ``ValueError``), so
``except MeshError`` catches every mesh problem while callers that care can tell the defects
apart. Each error carries the evidence in attributes: ``count`` (how many elements are
affected) and ``example`` (one offending vertex, edge or face index), besides its message.
"""

from __future__ import annotations

from ..errors import MeshError

__all__ = [
    "MeshError",
    "MeshFileError",
    "MeshDefectError",
    "DegenerateFaceError",
    "DuplicateFaceError",
    "UnreferencedVertexError",
    "NonManifoldError",
    "BoundaryError",
    "OrientationError",
    "DisconnectedError",
    "GenusError",
    "EmbeddingError",
]


class MeshFileError(MeshError):
    """A mesh file is missing, unreadable, of an unsupported format, or holds invalid data."""


class MeshDefectError(MeshError):
    """Base class of the defects found by :func:`sns_np.mesh.check`.

    Attributes
    ----------
    count : int or None
        Number of offending elements (faces, edges, vertices, components...).
    example : object or None
        One offending element: a face index, a vertex index or an edge ``(i, j)``.
    """

    def __init__(self, message: str, count=None, example=None):
        super().__init__(message)
        self.count = count
        self.example = example


class DegenerateFaceError(MeshDefectError):
    """A face repeats a vertex index or has (numerically) zero area."""


class DuplicateFaceError(MeshDefectError):
    """Two faces use the same three vertices (in any order)."""


class UnreferencedVertexError(MeshDefectError):
    """Some vertices are used by no face."""


class NonManifoldError(MeshDefectError):
    """An edge is shared by more than two faces, or a vertex's faces form several fans."""


class BoundaryError(MeshDefectError):
    """The mesh is open: some edges belong to exactly one face."""


class OrientationError(MeshDefectError):
    """Faces are inconsistently wound, or consistently wound but facing inwards."""


class DisconnectedError(MeshDefectError):
    """The mesh has more than one connected component."""


class GenusError(MeshDefectError):
    """The Euler characteristic is not 2 (the surface is not a topological sphere).

    ``count`` holds the genus found (``(2 - chi) / 2``).
    """


class EmbeddingError(MeshError):
    """The spherical embedding could not be made fold-free (bijective)."""
