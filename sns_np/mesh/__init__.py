"""Meshes: reading and checking, cotangent operators, spherical embedding, correspondences.

Heavy optional dependencies (meshio, trimesh, libigl) are imported inside the functions that
need them.
"""

from .icosphere import icosphere

__all__ = ["icosphere"]
