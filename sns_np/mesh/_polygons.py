"""Triangulating polygon faces without folds.

A k-gon is projected to its best-fit plane (Newell's normal, the polygon's vector area) and
split there:

* small polygons (k <= ``FAN_MAX``), vectorised over all faces of one size: the fan from the
  corner that maximises the smallest angle, among the fans whose triangles all turn the
  polygon's way in that plane. For a simple polygon such a fan covers it exactly once: the
  signed triangles of a fan sum to the polygon's winding number (0 or 1 at every point), so
  when none is negative they cannot overlap. Quads and pentagons of a smooth mesh keep the
  best-angled split; a non-convex quad gets its interior diagonal.
* larger polygons, and small ones without a valid fan: ear clipping in the plane. Only reflex
  corners can lie inside an ear, so a convex k-gon costs O(k) and a polygon with r reflex
  corners O(k r) (vectorised over the reflex corners).

A polygon that crosses or touches itself in its best-fit plane (or has zero vector area) has
no fold-free split; such faces occur in real meshes (nearly planar slivers of spot's control
mesh), so they are split as a fan like before and reported to the caller, not refused.

References
----------
Eberly, D. "Triangulation by ear clipping", Geometric Tools (2002).
"""

from __future__ import annotations

import numpy as np

#: polygons up to this size try the best-angled valid fan first
FAN_MAX = 8


def newell_normals(P):
    """Vector areas of polygons P (p, k, 3): 0.5 * sum_i c_i x c_{i+1} (Newell's method)."""
    Q = np.roll(P, -1, axis=1)
    return 0.5 * np.cross(P, Q).sum(axis=1)


def _fan_min_angles(V, T):
    """Smallest corner angle over the triangles of each fan, T (p, t, 3) -> (p,)."""
    X = V[T]
    worst = np.full(T.shape[:2], np.pi)
    for c in range(3):
        u = X[..., (c + 1) % 3, :] - X[..., c, :]
        v = X[..., (c + 2) % 3, :] - X[..., c, :]
        ang = np.arctan2(np.linalg.norm(np.cross(u, v), axis=-1), np.einsum("...i,...i", u, v))
        worst = np.minimum(worst, ang)
    return worst.min(axis=1)


def best_fans(V, P, n):
    """Best valid fan of each k-gon; P (p, k) corner indices, n (p, 3) vector areas.

    Returns (T, ok): T (p, k-2, 3) triangles and ok (p,) bool, False where no fan of that
    polygon keeps every triangle on the polygon's side of its plane.
    """
    p, k = P.shape
    X = V[P]
    scale = np.einsum("pi,pi->p", n, n)                         # |n|^2, area^2
    best = np.zeros((p, k - 2, 3), dtype=np.int64)
    best_angle = np.full(p, -np.inf)
    for a in range(k):
        R = np.roll(P, -a, axis=1)
        RX = np.roll(X, -a, axis=1)
        T = np.stack([np.stack([R[:, 0], R[:, i], R[:, i + 1]], axis=1)
                      for i in range(1, k - 1)], axis=1)        # (p, k-2, 3)
        # signed doubled areas of the fan triangles along n, relative to the polygon's
        e1 = RX[:, 1:-1] - RX[:, :1]
        e2 = RX[:, 2:] - RX[:, :1]
        turn = np.einsum("pti,pi->pt", np.cross(e1, e2), n)
        valid = (turn >= -1e-12 * scale[:, None]).all(axis=1) & (scale > 0)
        ang = np.where(valid, _fan_min_angles(V, T), -np.inf)
        better = ang > best_angle
        best[better], best_angle[better] = T[better], ang[better]
    return best, np.isfinite(best_angle)


def _segments_meet(P, Q, R, S):
    """Whether closed segments PQ and RS meet; P, Q, R, S (..., 2) -> (...,) bool."""
    def orient(a, b, c):
        return ((b[..., 0] - a[..., 0]) * (c[..., 1] - a[..., 1])
                - (b[..., 1] - a[..., 1]) * (c[..., 0] - a[..., 0]))
    o1, o2 = orient(P, Q, R), orient(P, Q, S)
    o3, o4 = orient(R, S, P), orient(R, S, Q)
    box = np.all((np.minimum(P, Q) <= np.maximum(R, S)) & (np.minimum(R, S) <= np.maximum(P, Q)),
                 axis=-1)
    return (o1 * o2 <= 0) & (o3 * o4 <= 0) & box


def crossing_small(X2):
    """Polygons X2 (p, k, 2) in which two non-adjacent edges meet -> (p,) bool."""
    p, k, _ = X2.shape
    i, j = np.triu_indices(k, 2)
    keep = ~((i == 0) & (j == k - 1))
    i, j = i[keep], j[keep]
    if i.size == 0:
        return np.zeros(p, dtype=bool)
    Y2 = np.roll(X2, -1, axis=1)
    return _segments_meet(X2[:, i], Y2[:, i], X2[:, j], Y2[:, j]).any(axis=1)


def crossing(x, y, block=1 << 20):
    """Whether two non-adjacent edges of one polygon (x, y (k,)) meet.

    The plane is cut into about sqrt(k) vertical strips; within a strip only edges whose
    clipped y-ranges overlap are compared (sorted by their lower ends), in blocks. Cost is
    about k sqrt(k) entries plus the overlapping pairs, not k^2.
    """
    k = x.size
    A = np.stack([x, y], axis=1)
    B = np.roll(A, -1, axis=0)
    lo, hi = np.minimum(A[:, 0], B[:, 0]), np.maximum(A[:, 0], B[:, 0])
    x0, x1 = float(lo.min()), float(hi.max())
    S = max(1, int(2 * np.sqrt(k)))
    w = (x1 - x0) / S
    if not w > 0:
        S, w = 1, 1.0
    s0 = np.clip(((lo - x0) / w).astype(np.int64), 0, S - 1)
    s1 = np.clip(((hi - x0) / w).astype(np.int64), 0, S - 1)
    reps = s1 - s0 + 1
    e = np.repeat(np.arange(k), reps)                           # one entry per edge and strip
    strip = s0[e] + (np.arange(e.size) - np.repeat(np.cumsum(reps) - reps, reps))
    # y-range of each edge clipped to its strip's x-interval
    cx0 = np.maximum(lo[e], x0 + strip * w)
    cx1 = np.minimum(hi[e], x0 + (strip + 1) * w)
    dx = B[e, 0] - A[e, 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        slope = np.where(dx != 0, (B[e, 1] - A[e, 1]) / dx, 0.0)
    ya = np.where(dx != 0, A[e, 1] + slope * (cx0 - A[e, 0]), A[e, 1])
    yb = np.where(dx != 0, A[e, 1] + slope * (cx1 - A[e, 0]), B[e, 1])
    pad = 1e-12 * (float(np.ptp(y)) + float(np.ptp(x)))
    ylo, yhi = np.minimum(ya, yb) - pad, np.maximum(ya, yb) + pad
    order = np.lexsort((ylo, strip))
    e, strip, ylo, yhi = e[order], strip[order], ylo[order], yhi[order]
    bounds = np.searchsorted(strip, np.arange(S + 1))
    end = np.empty(e.size, dtype=np.int64)
    for t in range(S):
        g0, g1 = bounds[t], bounds[t + 1]
        end[g0:g1] = g0 + np.searchsorted(ylo[g0:g1], yhi[g0:g1], side="right")
    count = end - np.arange(e.size) - 1                         # candidates after each entry
    starts = np.cumsum(count) - count
    total = int(count.sum())
    for b0 in range(0, total, block):
        flat = np.arange(b0, min(total, b0 + block))
        r = np.searchsorted(starts, flat, side="right") - 1
        i = e[r]
        j = e[r + 1 + (flat - starts[r])]
        d = np.abs(i - j)
        ok = (d != 1) & (d != k - 1) & (d != 0)
        i, j = i[ok], j[ok]
        if np.any(_segments_meet(A[i], B[i], A[j], B[j])):
            return True
    return False


def _plane_coords(X, n):
    """2D coordinates of points X (k, 3) in the plane with normal n, counter-clockwise."""
    n = n / np.linalg.norm(n)
    a = np.eye(3)[int(np.argmin(np.abs(n)))]
    u = np.cross(n, a)
    u /= np.linalg.norm(u)
    v = np.cross(n, u)                                          # u x v = n
    return X @ u, X @ v


def ear_clip(V, poly, n):
    """Triangles (k-2, 3) of one polygon ``poly`` (k,) with vector area n (3,), by ear clipping.

    Returns None when the polygon crosses or touches itself in its plane (or no ear is left).
    """
    poly = np.asarray(poly, dtype=np.int64)
    k = poly.size
    x, y = _plane_coords(V[poly], n)
    # relative tolerance for "turns left": the polygon's squared size
    tol = 1e-14 * float(np.ptp(x) ** 2 + np.ptp(y) ** 2)
    nxt = np.roll(np.arange(k), -1).tolist()
    prv = np.roll(np.arange(k), 1).tolist()
    if crossing(x, y):
        return None
    xs, ys = x.tolist(), y.tolist()

    def cross(i):
        a, b = prv[i], nxt[i]
        return (xs[i] - xs[a]) * (ys[b] - ys[i]) - (ys[i] - ys[a]) * (xs[b] - xs[i])

    reflex = np.zeros(k, dtype=bool)
    for i in range(k):
        reflex[i] = cross(i) <= tol
    n_reflex = int(reflex.sum())

    def is_ear(i):
        if reflex[i]:
            return False
        if n_reflex == 0:
            return True
        a, b = prv[i], nxt[i]
        idx = np.flatnonzero(reflex)
        idx = idx[(idx != a) & (idx != b)]
        if idx.size == 0:
            return True
        ax, ay, bx, by, cx, cy = xs[a], ys[a], xs[i], ys[i], xs[b], ys[b]
        px, py = x[idx], y[idx]
        # inside or on the closed triangle (a, i, b), counter-clockwise
        d1 = (bx - ax) * (py - ay) - (by - ay) * (px - ax)
        d2 = (cx - bx) * (py - by) - (cy - by) * (px - bx)
        d3 = (ax - cx) * (py - cy) - (ay - cy) * (px - cx)
        return not np.any((d1 >= -tol) & (d2 >= -tol) & (d3 >= -tol))

    out = []
    i, remaining, since_clip = 0, k, 0
    while remaining > 3:
        if is_ear(i):
            a, b = prv[i], nxt[i]
            out.append((poly[a], poly[i], poly[b]))
            nxt[a], prv[b] = b, a
            remaining -= 1
            for j in (a, b):
                was = reflex[j]
                reflex[j] = cross(j) <= tol
                n_reflex += int(reflex[j]) - int(was)
            i, since_clip = b, 0
        else:
            i = nxt[i]
            since_clip += 1
            if since_clip > remaining:       # no ear: only a crossing polygon lacks one
                return None
    a, b = prv[i], nxt[i]
    out.append((poly[a], poly[i], poly[b]))
    return np.array(out, dtype=np.int64)


def _any_fan(V, P):
    """The best-angled fan of each polygon P (p, k), valid or not (for faces without one)."""
    p, k = P.shape
    if k > FAN_MAX:
        T = np.stack([np.stack([P[:, 0], P[:, i], P[:, i + 1]], axis=1)
                      for i in range(1, k - 1)], axis=1)
        return T
    best, best_angle = None, None
    for a in range(k):
        R = np.roll(P, -a, axis=1)
        T = np.stack([np.stack([R[:, 0], R[:, i], R[:, i + 1]], axis=1)
                      for i in range(1, k - 1)], axis=1)
        ang = _fan_min_angles(V, T)
        if best is None:
            best, best_angle = T, ang
        else:
            better = ang > best_angle
            best[better], best_angle[better] = T[better], ang[better]
    return best


def triangulate(V, polys):
    """Triangles (m, 3) of all faces, in the faces' order, and two counts.

    Parameters
    ----------
    V : (n, 3) float array
    polys : list of sequences of vertex indices (at least 3 each, checked by the caller)

    Returns
    -------
    F : (m, 3) int array
    n_split : int, faces with more than 3 corners
    crossing : list of int, the faces that cross themselves (or have zero vector area) in
        their best-fit plane: no split of these is fold-free, so they are split as the
        best-angled fan (up to ``FAN_MAX`` corners) or the fan from their first corner.
    """
    sizes = np.fromiter((len(p) for p in polys), dtype=np.int64, count=len(polys))
    tris, order, crossed = [], [], []
    for k in np.unique(sizes).tolist():
        idx = np.flatnonzero(sizes == k)
        if k == 3:
            tris.append(np.array([polys[i] for i in idx], dtype=np.int64).reshape(-1, 3))
            order.append(idx)
            continue
        if k <= FAN_MAX:
            P = np.array([polys[i] for i in idx], dtype=np.int64)
            X = V[P]
            n = newell_normals(X)
            drop = np.argmax(np.abs(n), axis=1)                 # project along n's main axis
            keep = np.array([[1, 2], [0, 2], [0, 1]])[drop]
            X2 = np.take_along_axis(X, keep[:, None, :], axis=2)
            bad = crossing_small(X2) | ~np.any(n, axis=1)
            T, ok = best_fans(V, P, n)
            ok &= ~bad
            if bad.any():
                tris.append(_any_fan(V, P[bad]).reshape(-1, 3))
                order.append(np.repeat(idx[bad], k - 2))
                crossed += idx[bad].tolist()
            tris.append(T[ok].reshape(-1, 3))
            order.append(np.repeat(idx[ok], k - 2))
            rest = [(f, P[j], n[j]) for j, f in enumerate(idx.tolist()) if not (ok[j] or bad[j])]
        else:
            rest = []
            for f in idx.tolist():
                P = np.asarray(polys[f], dtype=np.int64)
                rest.append((f, P, newell_normals(V[P][None])[0]))
        for f, P, n in rest:
            T = ear_clip(V, P, n) if np.any(n) else None
            if T is None:
                T = _any_fan(V, P[None])[0]
                crossed.append(f)
            tris.append(T)
            order.append(np.full(k - 2, f))
    F = np.concatenate(tris) if tris else np.zeros((0, 3), dtype=np.int64)
    # keep the file's face order (triangles of one polygon stay together)
    F = F[np.argsort(np.concatenate(order), kind="stable")]
    return F, int((sizes > 3).sum()), sorted(crossed)
