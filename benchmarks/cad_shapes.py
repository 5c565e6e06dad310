"""Closed genus-0 meshes with sharp edges, built here, and their exact flat or round parts.

The shared meshes are all organic: scans and sculpts whose creases are rounded over several
triangles. A user's CAD part has edges that are sharp (the normal jumps across one edge of the
mesh) and flat faces whose triangulation says nothing about the shape. These meshes test the
fit there, and their geometry is known in closed form away from the edges:

* ``cube``: the cube [-1, 1]^3, each face a 32 x 32 grid of squares split in two (6,146
  vertices). Flat faces, twelve convex edges.
* ``jack``: seven unit voxels, a centre and one on each side of it (a 3-D cross 3 wide), each
  exposed unit face a 16 x 16 grid (7,682 vertices). Convex and concave edges, and corners
  where three concave edges meet.
* ``jack_coarse``: the jack with a 6 x 6 grid per unit face (1,082 vertices), the low end of
  the vertex counts a user brings: a triangle along an edge is a sixth of the jack's arm.
* ``cylinder``: radius 1, height 2.5, 96 segments round, 24 rows up the side, and caps of 15
  rings inside the rim, fanned into their centres (5,282 vertices): a flat cap meets the round
  side at a sharp rim, and the caps' triangles shrink to slivers at the centre.

:func:`exact_away_from_edges` gives, at points of a fitted surface more than ``margin`` from
the edges, the exact unit normal and mean curvature there (H = 0 on the flat parts, 1/(2 R) on
the cylinder's side; the sign as the fitted H, which is positive on a sphere here).
"""

from __future__ import annotations

import numpy as np

CAD = ("cube", "jack", "cylinder", "jack_coarse")
_JACK = [(0, 0, 0), (1, 0, 0), (-1, 0, 0), (0, 1, 0), (0, -1, 0), (0, 0, 1), (0, 0, -1)]
#: the polycubes: their voxels (unit cubes centred at integer points), grid per unit face, size
POLYCUBES = {"cube": ([(0, 0, 0)], 32, 2.0), "jack": (_JACK, 16, 1.0),
             "jack_coarse": (_JACK, 6, 1.0)}


def cad_mesh(name):
    """``(V, F)`` of a CAD-like case, outward-oriented."""
    if name in POLYCUBES:
        return _polycube(*POLYCUBES[name])
    if name == "cylinder":
        return _cylinder(1.0, 2.5, 96, 24, 16)
    raise ValueError(f"unknown CAD case {name!r}; expected one of {', '.join(CAD)}")


def _polycube(voxels, n, size=1.0):
    """The surface of a union of unit voxels centred at integer points, every exposed unit
    face an ``n`` x ``n`` grid of squares, each split in two; scaled by ``size``."""
    occupied = set(map(tuple, voxels))
    t = np.linspace(-0.5, 0.5, n + 1)
    A, B = np.meshgrid(t, t, indexing="ij")
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    a, b, c, d = (k.ravel() for k in (i * (n + 1) + j, (i + 1) * (n + 1) + j,
                                      (i + 1) * (n + 1) + j + 1, i * (n + 1) + j + 1))
    grid_faces = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    Vs, Fs, offset = [], [], 0
    for v in occupied:
        for axis in range(3):
            for side in (-1, 1):
                nb = list(v)
                nb[axis] += side
                if tuple(nb) in occupied:
                    continue
                u, w = (axis + 1) % 3, (axis + 2) % 3       # (u, w, axis) is right-handed
                P = np.empty(((n + 1) ** 2, 3))
                P[:, axis] = v[axis] + 0.5 * side
                P[:, u] = v[u] + A.ravel()
                P[:, w] = v[w] + B.ravel()
                # the grid's winding (u, then w) faces +axis: reversed on the - side
                f = grid_faces if side > 0 else grid_faces[:, ::-1]
                Vs.append(P)
                Fs.append(f + offset)
                offset += len(P)
    return _merge(np.concatenate(Vs) * size, np.concatenate(Fs))


def _cylinder(R, h, segments, rows, rings):
    """A capped cylinder about the z axis: the side a ``segments`` x ``rows`` grid, each cap
    ``rings - 1`` concentric rings of ``segments`` points inside the rim, fanned into its
    centre."""
    th = 2 * np.pi * np.arange(segments) / segments
    ring = np.stack([np.cos(th), np.sin(th)], 1)
    loops = [np.c_[R * ring, np.full(segments, z)] for z in np.linspace(-h / 2, h / 2,
                                                                          rows + 1)]
    top = [np.c_[R * r * ring, np.full(segments, h / 2)] for r in
           np.linspace(1, 0, rings + 1)[1:-1]]
    bottom = [np.c_[R * r * ring, np.full(segments, -h / 2)] for r in
              np.linspace(1, 0, rings + 1)[1:-1]]
    # one strip of loops from the bottom centre to the top centre, outward by construction
    strip = bottom[::-1] + loops + top
    V = np.concatenate(strip + [np.array([[0, 0, -h / 2], [0, 0, h / 2]])])
    k = np.arange(segments)
    F = []
    for s in range(len(strip) - 1):
        a, b = s * segments + k, s * segments + (k + 1) % segments
        c, d = a + segments, b + segments
        F += [np.stack([a, b, d], 1), np.stack([a, d, c], 1)]
    lo, hi = len(V) - 2, len(V) - 1
    last = (len(strip) - 1) * segments
    F += [np.stack([np.full(segments, lo), (k + 1) % segments, k], 1),
          np.stack([np.full(segments, hi), last + k, last + (k + 1) % segments], 1)]
    return _merge(V, np.concatenate(F))


def _merge(V, F, decimals=9):
    """Merge coincident vertices (the grids of neighbouring faces share their borders)."""
    _, first, inverse = np.unique(np.round(V, decimals), axis=0, return_index=True,
                                  return_inverse=True)
    return V[first], inverse.ravel()[F]


def exact_away_from_edges(name, x, margin=0.1):
    """At surface points ``x`` (n, 3) in the mesh's units: a mask of the points more than
    ``margin`` from every edge of the CAD shape, their exact unit normals and mean
    curvature (the parts in between are left to the measures against the mesh)."""
    x = np.asarray(x, dtype=np.float64)
    if name == "cylinder":
        r = np.linalg.norm(x[:, :2], axis=1)
        side = (np.abs(x[:, 2]) < 1.25 - margin) & (r > 1 - margin)
        cap = (r < 1 - margin) & (np.abs(x[:, 2]) > 1.25 - margin)
        n = np.zeros_like(x)
        n[side, :2] = x[side, :2] / r[side, None]
        n[cap, 2] = np.sign(x[cap, 2])
        return side | cap, n, np.where(side, 0.5, 0.0)
    if name not in POLYCUBES:
        raise ValueError(f"unknown CAD case {name!r}; expected one of {', '.join(CAD)}")
    voxels, _, size = POLYCUBES[name]
    occupied = set(map(tuple, voxels))
    y = x / size
    # the face a point is on: the nearest plane of the voxel grid (half-integer coordinates)
    plane = np.floor(y) + 0.5
    axis = np.argmin(np.abs(y - plane), axis=1)
    rows = np.arange(len(y))
    # in the face's other coordinates, more than margin inside its unit square
    border = 0.5 - np.abs(y - np.round(y))
    border[rows, axis] = np.inf
    inside = border.min(axis=1) * size > margin
    # the outward normal points away from the occupied one of the plane's two voxels
    below = np.round(y).astype(int)
    below[rows, axis] = np.floor(y[rows, axis]).astype(int)
    sign = np.array([1.0 if tuple(v) in occupied else -1.0 for v in below])
    n = np.zeros_like(x)
    n[rows, axis] = sign
    return inside, n, np.zeros(len(x))
