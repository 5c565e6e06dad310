"""Training points drawn where the fit is still wrong: error-weighted sampling.

Uniform sampling by area spends most samples where the network is already right (the smooth
flanks of a cow) and few on what it still misses (ears, horns, eyes). This sampler keeps, for
each cell of the mesh (a face, or a patch of neighbouring faces on a fine mesh), a running mean
of the per-sample loss ``e = |S(p) - q|^2 + lambda |n - n_t|^2`` of the points drawn there, and
draws cell ``c`` with probability

    P(c) = a_c ((1 - m) + m sqrt(e_c) / sum_k a_k sqrt(e_k))        (a: area fractions)

a mixture of the uniform draw and the draw proportional to ``a_c |residual|`` (the density that
minimises the variance of a squared-error gradient estimate). Within a cell, points stay
uniform by area. Each point carries the importance weight ``a_c / P(c)``, so the weighted loss
has the uniform loss as its expectation: the objective is the same, only its estimate is less
noisy where the error is. The uniform part (``1 - m``) keeps every weight below ``1 / (1 - m)``.

The draw is stratified: the cells are ordered along a space-filling (Morton) curve through
their centroids, and a batch of ``n`` points takes one point from each of the ``n`` equal
slices of the cumulative probability along that order (jittered systematic sampling). Every
point still has the distribution ``P`` (so the weights and the expectation are unchanged), but
a batch covers the surface evenly instead of in random clumps, which takes much of the noise
out of a step's gradient.

Measured in docs/fitting.md, section 2 ("Sampling weighted by the error").
"""

from __future__ import annotations

import numpy as np

#: mixture weight of the error-proportional draw, per-step decay of the running error sums,
#: how often (steps) the cell probabilities are recomputed, and whether a batch is stratified
#: along the cells' space-filling order
ERROR_SAMPLING = {"mix": 0.8, "decay": 0.99, "every": 10, "stratified": True}

#: samples a cell should receive, on average, within the running window of a uniform draw
#: (about ``1 / (1 - decay)`` steps of ``batch`` samples); finer meshes are grouped into
#: patches so that each cell's error estimate rests on that many samples
SAMPLES_PER_CELL = 8


def face_cells(centroids, areas, n_cells, seed=0):
    """Group faces into about ``n_cells`` patches of similar area: each face joins the nearest
    of ``n_cells`` seed faces drawn with probability proportional to area.

    Parameters
    ----------
    centroids : (m, 3) float array, face centroids
    areas : (m,) float array, face areas
    n_cells : int, the number of patches (every face is its own cell when ``m <= n_cells``)
    seed : int, seed of the draw of the seed faces

    Returns
    -------
    labels : (m,) int array, the cell of each face, ``0 <= labels < n_cells``, every cell used

    Examples
    --------
    >>> from sns_np.mesh import icosphere, face_areas
    >>> V, F = icosphere(3)
    >>> labels = face_cells(V[F].mean(axis=1), face_areas(V, F), 100)
    >>> int(labels.max()) + 1, len(np.unique(labels))
    (100, 100)
    """
    from scipy.spatial import cKDTree
    m = len(areas)
    if m <= n_cells:
        return np.arange(m)
    g = np.random.default_rng(seed)
    seeds = g.choice(m, size=n_cells, replace=False, p=areas / areas.sum())
    labels = cKDTree(centroids[seeds]).query(centroids)[1]
    # a seed face is nearest to itself, so no cell is empty; renumber in case of ties
    return np.unique(labels, return_inverse=True)[1].reshape(-1)


def morton_order(X, bits=10):
    """The order of the points ``X`` (n, 3) along a Morton (Z-order) curve through their
    bounding cube: points close in the order are close in space.

    Each coordinate is quantised to ``bits`` bits on the cube's grid and the bits are
    interleaved into one integer key; the order sorts the keys (stably).

    Examples
    --------
    >>> X = np.array([[1.0, 1.0, 1.0], [0.0, 0.0, 0.0], [0.9, 1.0, 1.0], [0.1, 0.0, 0.0]])
    >>> morton_order(X).tolist()
    [1, 3, 2, 0]
    """
    X = np.asarray(X, dtype=np.float64)
    lo = X.min(axis=0)
    side = float((X.max(axis=0) - lo).max()) or 1.0
    top = 2 ** bits - 1
    Q = np.clip(((X - lo) / side * top).astype(np.int64), 0, top)
    key = np.zeros(len(X), dtype=np.int64)
    for b in range(bits):
        for d in range(3):
            key |= ((Q[:, d] >> b) & 1) << (3 * b + d)
    return np.argsort(key, kind="stable")


class ErrorSampler:
    """Draws a mesh target's training points with probability that follows the recent error
    and returns their importance weights.

    Parameters
    ----------
    target : a mesh target, or an analytic map's (whose cells are geodesic triangles of the
        parameter sphere): ``face_area``, ``face_centroid`` and ``sample_faces(face, rng)``
    batch : int, samples per step (sizes the cells: see ``SAMPLES_PER_CELL``)
    mix, decay, every, stratified : as ``ERROR_SAMPLING`` (``stratified``: one point from
        each equal slice of the cumulative probability along the cells' Morton order, instead
        of independent draws; the module docstring)

    Examples
    --------
    >>> from sns_np.shapes import Ellipsoid
    >>> from sns_np.surface._targets import _MeshTarget
    >>> V, F = Ellipsoid(1.0, 1.3, 0.7).mesh(2)
    >>> s = ErrorSampler(_MeshTarget(V, F, verbose=False), batch=64)
    >>> g = np.random.default_rng(0)
    >>> p, q, n, w = s.sample(64, g)
    >>> s.observe(np.ones(64))                       # the per-sample errors of this draw
    >>> p.shape, float(w.mean())                     # uniform until errors differ
    ((64, 3), 1.0)
    """

    def __init__(self, target, batch, mix=ERROR_SAMPLING["mix"],
                 decay=ERROR_SAMPLING["decay"], every=ERROR_SAMPLING["every"],
                 stratified=ERROR_SAMPLING["stratified"]):
        if not 0.0 <= mix < 1.0:
            raise ValueError(f"mix must be in [0, 1), got {mix}")
        if not 0.0 < decay < 1.0:
            raise ValueError(f"decay must be in (0, 1), got {decay}")
        if int(every) < 1:
            raise ValueError(f"every must be an integer >= 1, got {every}")
        if not isinstance(stratified, (bool, np.bool_)):
            raise ValueError(f"stratified must be True or False, got {stratified!r}")
        self.target = target
        self.mix, self.decay, self.every = float(mix), float(decay), int(every)
        self.stratified = bool(stratified)
        areas = np.asarray(target.face_area, dtype=np.float64)
        n_cells = max(1, int(batch / (1.0 - self.decay) / SAMPLES_PER_CELL))
        self.labels = face_cells(target.face_centroid, areas, n_cells)
        k = int(self.labels.max()) + 1
        # faces ordered by cell, with the cumulative area along that order: a point of cell c
        # is a uniform draw of area in [start_c, start_c + a_c)
        self._order = np.argsort(self.labels, kind="stable")
        self._cum_face = np.cumsum(areas[self._order])
        cell_area = np.bincount(self.labels, weights=areas, minlength=k)
        self._start = np.concatenate([[0.0], np.cumsum(cell_area)[:-1]])
        self.area = cell_area / cell_area.sum()
        # the cells along a Morton curve through their area centroids: the order in which a
        # stratified draw walks the cumulative probability
        centroid = np.stack([np.bincount(self.labels, weights=areas * target.face_centroid[:, d],
                                         minlength=k) for d in range(3)], axis=1)
        self._curve = morton_order(centroid / cell_area[:, None])
        self.err_sum = np.zeros(k)
        self.count = np.zeros(k)
        self.steps = 0
        self._set_probabilities(self.area)
        self._cells = None

    @property
    def n_cells(self):
        return len(self.area)

    def _set_probabilities(self, prob):
        self.prob = prob
        self._cum = np.cumsum(prob[self._curve])        # along the curve
        self.weight = self.area / np.maximum(prob, np.finfo(float).tiny)

    def sample(self, n, rng, **options):
        """``(p, q, normals, weights)`` of ``n`` points; ``weights`` average 1 in expectation.
        ``options`` go to the target's ``sample_faces`` (an analytic map's ``jets`` and
        ``second``: then ``(p, q, normals, JT, ST, weights)``, its jets before the weights)."""
        u = rng.random(n)
        if self.stratified:         # one point in each of n equal slices
            u = (np.arange(n) + u) / n
        c = self._curve[np.minimum(np.searchsorted(self._cum, u * self._cum[-1], side="right"),
                                   self.n_cells - 1)]
        u = self._start[c] + rng.random(n) * self.area[c] * self._cum_face[-1]
        i = np.searchsorted(self._cum_face, u, side="right")
        face = self._order[np.minimum(i, len(self._order) - 1)]
        # rounding can step over a cell's edge: keep the face inside the drawn cell
        bad = self.labels[face] != c
        if bad.any():
            first = np.searchsorted(self.labels[self._order], c[bad], side="left")
            face[bad] = self._order[first]
        self._cells = c
        return (*self.target.sample_faces(face, rng, **options), self.weight[c])

    def observe(self, err):
        """Record the per-sample errors of the last draw (unweighted, as the loss's
        ``parts["pointwise"]``); every ``every`` steps the cell probabilities follow them."""
        if self._cells is None or len(err) != len(self._cells):
            raise ValueError(f"observe needs one error per sample of the last draw "
                             f"({0 if self._cells is None else len(self._cells)}), "
                             f"got {len(err)}")
        k = self.n_cells
        self.err_sum *= self.decay
        self.count *= self.decay
        self.err_sum += np.bincount(self._cells, weights=np.asarray(err, np.float64),
                                    minlength=k)
        self.count += np.bincount(self._cells, minlength=k)
        self._cells = None
        self.steps += 1
        if self.steps % self.every == 0:
            self._update()

    def _update(self):
        seen = self.count > 0
        if not seen.any():
            return
        e = np.empty(self.n_cells)
        e[seen] = self.err_sum[seen] / self.count[seen]
        # a cell not drawn yet gets the area-weighted mean of the others
        e[~seen] = (self.area[seen] @ e[seen]) / self.area[seen].sum()
        s = np.sqrt(np.maximum(e, 0.0))
        norm = self.area @ s
        if not np.isfinite(norm) or norm <= 0.0:
            self._set_probabilities(self.area)
            return
        self._set_probabilities(self.area * ((1.0 - self.mix) + self.mix * s / norm))

    def state_dict(self):
        """The running sums, the probabilities in force and the step count (what a
        checkpoint keeps: a resumed fit draws exactly as the uninterrupted one)."""
        return {"err_sum": self.err_sum.copy(), "count": self.count.copy(),
                "prob": self.prob.copy(), "steps": np.array(self.steps)}

    def load_state_dict(self, state):
        arrays = {k: np.asarray(state[k], dtype=np.float64) for k in ("err_sum", "count", "prob")}
        for k, v in arrays.items():
            if v.shape != (self.n_cells,):
                raise ValueError(f"sampler state {k!r} has shape {v.shape}; this target has "
                                 f"{self.n_cells} cells")
        self.err_sum, self.count = arrays["err_sum"], arrays["count"]
        self.steps = int(state["steps"])
        self._set_probabilities(arrays["prob"])
