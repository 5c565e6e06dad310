"""Render the figure gallery of the documentation (docs/gallery.md) into PNG files.

Four figures, each computed from a fitted neural surface with no mesh in between (the meshes
below are only the icosphere pushed through the surface map, for drawing):

  gallery_spot_mean_curvature.png  Keenan Crane's spot, fitted with the library's defaults,
                                   coloured by its exact mean curvature H
  gallery_eigenmodes.png           the first non-constant Laplace-Beltrami eigenmodes of the
                                   fitted spot: Rayleigh-Ritz (the library's default) and the
                                   paper's neural method, each panel titled with its eigenvalue
  gallery_heat_flow.png            heat flow of a hot spot on the fitted spot (spectral scheme)
  gallery_mcf.png                  mean curvature flow of a wobbly ellipsoid, coloured by H
                                   (spot's thin legs, ears and horns are expected to pinch off)

Run (from any folder; the default output folder is the project's docs/images):

    python examples/gallery.py                       # fits spot: 15-19 minutes on 2 cores
    python examples/gallery.py --model spot.npz      # reuse a fitted spot: 5-10 minutes
    python examples/gallery.py --save-model spot.npz # keep the fit for the next run
    python examples/gallery.py --quick --out /tmp/g  # a smoke run on an ellipsoid: seconds

The full run fits ``../shared/data/meshes/spot_triangulated.obj`` with
``SphericalNeuralSurface.fit`` (its time budget: 540 s for a detailed mesh such as spot), then
spends 5-10 minutes on the eigenmodes (most of it the neural ones), heat flow, mean curvature
flow and rendering: 18 min 40 s in all on the project's busy 2-core machine (load about 10),
5 min for the figures from a saved model on a quieter one. Every random choice is seeded
(``--seed``); the fit is time-budgeted, so its step count, and with it the pictures' fine
detail, depends on the machine's speed. Nothing is written outside ``--out`` (default
docs/images) unless ``--save-model`` asks for it; each PNG is written atomically (a temporary
file renamed into place).

Needs matplotlib, the ``plots`` extra: ``pip install 'sns-np[plots]'``.
"""

import argparse
import sys
import time
from pathlib import Path

import numpy as np
from _common import SMOKE, clear_errors, output_dir, shared_mesh, write_atomically

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_OUT = ROOT / "docs" / "images"
NAMES = ("gallery_spot_mean_curvature.png", "gallery_eigenmodes.png", "gallery_heat_flow.png",
         "gallery_mcf.png")
DPI = 110

#: budgets of the full run and of ``--quick`` (a small ellipsoid fit; seconds)
FULL = dict(level=6, panel_level=5, k=5, ritz={}, neural=dict(), heat_k=200,
            heat_times=(0.0, 0.005, 0.02, 0.06, 0.2), heat_width=0.07,
            mcf_fit=dict(width=64, depth=2, steps=1500, batch=1024),
            mcf=dict(t_end=0.1, dt=1e-3, refit_steps=10), mcf_times=(0.0, 0.025, 0.05, 0.1))
QUICK = dict(level=3, panel_level=3, k=3, ritz=dict(L=8),
             neural=dict(steps=60, batch=256, n_train=1000, n_eval=2000), heat_k=20,
             heat_times=(0.0, 0.02, 0.1), heat_width=0.5,
             mcf_fit=dict(width=16, depth=1, steps=60, batch=256),
             mcf=dict(t_end=0.02, dt=0.005, refit_steps=2, n_points=256),
             mcf_times=(0.0, 0.01, 0.02))


def need_matplotlib():
    """Import matplotlib with a file-only backend, or say which extra provides it."""
    try:
        import matplotlib
    except ImportError:
        raise ImportError("gallery.py needs matplotlib, the 'plots' extra: "
                          "pip install 'sns-np[plots]'") from None
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


# ---------------------------------------------------------------------------- rendering

class View:
    """An orthographic camera: ``up`` is the shape's up axis, ``front`` the direction it faces;
    ``azim`` turns the camera about ``up`` away from ``front``, ``elev`` raises it (degrees)."""

    def __init__(self, up=(0, 0, 1), front=(1, 0, 0), azim=40.0, elev=20.0):
        up = np.asarray(up, float) / np.linalg.norm(up)
        front = np.asarray(front, float)
        front = front - (front @ up) * up
        front /= np.linalg.norm(front)
        a, e = np.radians(azim), np.radians(elev)
        self.shape_up, self.shape_front = up, front
        side = np.cross(up, front)
        self.eye = np.cos(e) * (np.cos(a) * front + np.sin(a) * side) + np.sin(e) * up
        self.up = up - (up @ self.eye) * self.eye
        self.up /= np.linalg.norm(self.up)
        self.right = np.cross(self.up, self.eye)          # right x up = towards the viewer
        light = self.eye + 0.6 * self.up - 0.4 * self.right   # from the upper left, in front
        self.light = light / np.linalg.norm(light)


def vertex_normals(V, F):
    """Area-weighted vertex normals of a triangle mesh (outward for outward faces)."""
    N = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    out = np.zeros_like(V)
    for i in range(3):
        np.add.at(out, F[:, i], N)
    return out / np.maximum(np.linalg.norm(out, axis=1, keepdims=True), 1e-300)


def draw_surface(ax, V, F, values, cmap, norm, view, extent=None):
    """Draw a shaded, coloured triangle mesh into a 2-D axes (painter's algorithm).

    Back faces are culled, the rest sorted far to near and drawn as one PolyCollection; each
    face gets the colour of its mean vertex value times a Lambert term of its mean vertex
    normal. ``extent`` (xmin, xmax, ymin, ymax) fixes the framing across panels.
    """
    from matplotlib.collections import PolyCollection

    X = np.stack([V @ view.right, V @ view.up], axis=1)
    depth = (V @ view.eye)[F].mean(axis=1)
    face_n = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    keep = np.flatnonzero(face_n @ view.eye > 0)
    keep = keep[np.argsort(depth[keep])]
    n = vertex_normals(V, F)[F[keep]].mean(axis=1)
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
    shade = 0.45 + 0.55 * np.clip(n @ view.light, 0.0, 1.0)
    rgba = cmap(norm(np.nanmean(values[F[keep]], axis=1)))
    rgba[:, :3] *= shade[:, None]
    # edges in the face colour hide the hairline seams that antialiasing leaves between faces
    ax.add_collection(PolyCollection(X[F[keep]], facecolors=rgba, edgecolors=rgba,
                                     linewidths=0.2, antialiased=False))
    if extent is None:
        extent = framing([V], view)
    ax.set(xlim=extent[:2], ylim=extent[2:], aspect="equal")
    ax.axis("off")


def framing(meshes, view, margin=0.03):
    """Common (xmin, xmax, ymin, ymax) of the projections of several vertex arrays."""
    X = np.concatenate([np.stack([V @ view.right, V @ view.up], axis=1) for V in meshes])
    lo, hi = X.min(axis=0), X.max(axis=0)
    pad = margin * (hi - lo).max()
    return lo[0] - pad, hi[0] + pad, lo[1] - pad, hi[1] + pad


def symmetric_limit(values, q=98.0):
    """A robust symmetric colour limit: the q-th percentile of |values| (finite ones)."""
    v = np.abs(values[np.isfinite(values)])
    lim = float(np.percentile(v, q)) if v.size else 1.0
    return lim if lim > 0 else 1.0


def save(fig, path, dpi=DPI):
    write_atomically(path, lambda tmp: fig.savefig(tmp, dpi=dpi, format="png"))
    size = path.stat().st_size / 1024
    print(f"wrote {path} ({size:.0f} KB)", flush=True)


# ---------------------------------------------------------------------------- computations

def spot_surface(args, quick):
    """(surface, label, view) of the main figures: the fitted spot, or a small ellipsoid fit."""
    from sns_np import SphericalNeuralSurface
    if quick:
        from sns_np.shapes import Ellipsoid
        S, _ = SphericalNeuralSurface.fit_shape(Ellipsoid(1.0, 1.3, 0.7), width=32, depth=2,
                                                steps=100, batch=512, n_eval=500,
                                                seed=args.seed, progress=False)
        return S, "ellipsoid (1, 1.3, 0.7), 32 x 2 network, 100 steps", View()
    # spot stands on its feet along +y and looks along -z (its tail points to +z)
    view = View(up=(0, 1, 0), front=(0, 0, -1), azim=55.0, elev=15.0)
    if args.model:
        S = SphericalNeuralSurface.load(args.model)
        return S, f"{Path(args.model).name}", view
    from sns_np.mesh import load
    path = Path(args.mesh) if args.mesh else shared_mesh("spot_triangulated.obj")
    V, F = load(path)[:2]
    print(f"fitting {path.name} ({len(V)} vertices) with the library's defaults "
          f"(a time budget of several minutes)", flush=True)
    S, report = SphericalNeuralSurface.fit(V, F, seed=args.seed, source=path.name)
    print(report.summary(), flush=True)
    if args.save_model:
        S.save(args.save_model)
        print(f"saved {args.save_model}", flush=True)
    return S, f"{path.name}, {report.steps} steps", view


class GaussianBump:
    """An ambient hot spot ``f(x) = exp(-|x - c|^2 / (2 s^2))`` with exact jets (field
    protocol, in R^3); :class:`sns_np.shapes.PullbackField` carries it to the sphere."""

    def __init__(self, center, width):
        self.c, self.s2 = np.asarray(center, float), float(width) ** 2

    def jet(self, x, order=0):
        d = np.asarray(x, float) - self.c
        v = np.exp(-0.5 * np.einsum("ki,ki->k", d, d) / self.s2)
        if order == 0:
            return v
        g = -(v / self.s2)[:, None] * d
        if order == 1:
            return v, g
        h = (v / self.s2 ** 2)[:, None, None] * np.einsum("ki,kj->kij", d, d) \
            - (v / self.s2)[:, None, None] * np.eye(3)
        return v, g, h


# ---------------------------------------------------------------------------- figures

def figure_mean_curvature(plt, S, label, view, cfg, path):
    from matplotlib.colors import Normalize

    V, F, data = S.to_mesh(cfg["level"])
    H = data["H"]
    lim = symmetric_limit(H)
    fig, ax = plt.subplots(figsize=(7.2, 5.6))
    cmap, norm = plt.get_cmap("RdBu_r"), Normalize(-lim, lim)
    draw_surface(ax, V, F, H, cmap, norm, view)
    bar = fig.colorbar(plt.cm.ScalarMappable(norm, cmap), ax=ax, shrink=0.75, extend="both")
    bar.set_label("mean curvature H (mesh units$^{-1}$)\n"
                  "H > 0 convex, H < 0 saddle-like or concave (outward normals)")
    ax.set_title(f"{label}: exact H of the neural surface\n(colour limits: 98th percentile "
                 f"of |H|; H ranges over [{np.nanmin(H):.3g}, {np.nanmax(H):.3g}])",
                 fontsize=10)
    fig.tight_layout()
    save(fig, path)
    plt.close(fig)


def figure_eigenmodes(plt, S, view, cfg, seed, path):
    from matplotlib.colors import Normalize

    from sns_np.spectral import eigenmodes

    k = cfg["k"]
    t0 = time.perf_counter()
    ritz = eigenmodes(S, k, method="ritz", **cfg["ritz"])
    print(f"Rayleigh-Ritz, {k} modes: {ritz.seconds:.1f} s; eigenvalues "
          f"{np.round(ritz.eigenvalues, 4).tolist()}", flush=True)
    neural = eigenmodes(S, k, method="neural", rng=seed, **cfg["neural"])
    print(f"neural, {k} modes: {neural.seconds:.1f} s; eigenvalues "
          f"{np.round(neural.eigenvalues, 4).tolist()}", flush=True)
    V, F, data = S.to_mesh(cfg["panel_level"], fields=False)
    P = data["sphere"]
    rows = [("Rayleigh-Ritz", ritz.evaluate(P), ritz), ("neural (paper)", neural.evaluate(P),
                                                        neural)]
    ref = rows[0][1]
    extent = framing([V], view)
    fig, axes = plt.subplots(2, k, figsize=(2.4 * k, 5.4), squeeze=False)
    cmap = plt.get_cmap("RdBu_r")
    for r, (name, Phi, res) in enumerate(rows):
        for i in range(k):
            phi = Phi[:, i]
            if r == 1 and phi @ ref[:, i] < 0:   # eigenfunctions have no sign: match Ritz's
                phi = -phi
            lim = np.nanmax(np.abs(phi))
            ax = axes[r, i]
            draw_surface(ax, V, F, phi, cmap, Normalize(-lim, lim), view, extent)
            se = "" if res.stderr is None else f" ± {res.stderr[i]:.2f}"
            ax.set_title(f"{name}\n$\\lambda_{i + 1}$ = {res.eigenvalues[i]:.3f}{se}",
                         fontsize=9)
    fig.suptitle("Laplace-Beltrami eigenmodes $\\Delta_S \\varphi = -\\lambda \\varphi$ "
                 "(red > 0 > blue, each mode on its own symmetric scale)", fontsize=10)
    fig.tight_layout()
    save(fig, path, dpi=100)                 # ten shaded panels: keeps the file near 300 KB
    plt.close(fig)
    return ritz, neural, time.perf_counter() - t0


def figure_heat(plt, S, view, cfg, path):
    from matplotlib.colors import PowerNorm

    from sns_np.flows import heat_flow
    from sns_np.shapes import PullbackField

    V, F, data = S.to_mesh(cfg["panel_level"], fields=False)
    P = data["sphere"]
    # the hot spot sits on top of the shape, straight above the centre of its bounding box
    # (on spot: its withers, behind the head)
    lo, hi = V.min(axis=0), V.max(axis=0)
    d = V - (lo + hi) / 2
    height = d @ view.shape_up
    off_axis = np.linalg.norm(d - height[:, None] * view.shape_up, axis=1)
    near = off_axis < 0.05 * np.linalg.norm(hi - lo)
    center = V[near][np.argmax(height[near])]
    width = cfg["heat_width"] * np.linalg.norm(hi - lo)
    field = PullbackField(GaussianBump(center, width), S)
    times = np.asarray(cfg["heat_times"])
    res = heat_flow(S, field, float(times[-1]), 1e-3, method="spectral", times=times,
                    k=cfg["heat_k"], eigen_options=cfg["ritz"])
    print(f"heat flow (spectral, {cfg['heat_k']} modes): {res.seconds:.1f} s, projection "
          f"residual {res.info['projection_residual']:.2e}", flush=True)
    values = [field.jet(P, 0)] + [f(P) for f in res.fields[1:]]
    vmax = max(float(np.nanmax(v)) for v in values)
    extent = framing([V], view)
    n = len(values)
    fig, axes = plt.subplots(1, n, figsize=(2.5 * n + 1.0, 3.0), layout="constrained")
    # a square-root scale shows the cool tail as well as the peak
    cmap, norm = plt.get_cmap("inferno"), PowerNorm(0.5, 0.0, vmax)
    for ax, v, t in zip(axes, values, res.times):
        draw_surface(ax, V, F, v, cmap, norm, view, extent)
        ax.set_title(f"t = {t:g}", fontsize=10)
    fig.colorbar(plt.cm.ScalarMappable(norm, cmap), ax=axes, shrink=0.8, pad=0.02,
                 label="temperature f")
    fig.suptitle("heat flow $f_t = \\Delta_S f$ of a hot spot (one colour scale)", fontsize=10)
    save(fig, path)
    plt.close(fig)
    return res


def figure_mcf(plt, cfg, seed, path):
    from matplotlib.colors import Normalize

    from sns_np import SphericalNeuralSurface
    from sns_np.flows import mean_curvature_flow
    from sns_np.shapes import PerturbedEllipsoid

    shape = PerturbedEllipsoid(1.2, 1.0, 0.8, amplitude=0.12, frequency=4.0)
    S, report = SphericalNeuralSurface.fit_shape(shape, seed=seed, progress=False,
                                                 **cfg["mcf_fit"])
    print(f"wobbly ellipsoid fitted: {report.steps} steps, {report.seconds:.1f} s", flush=True)
    o = cfg["mcf"]
    res = mean_curvature_flow(S, o["t_end"], o["dt"], times=cfg["mcf_times"], rng=seed,
                              mesh_level=cfg["panel_level"],
                              **{key: v for key, v in o.items() if key not in ("t_end", "dt")})
    print(f"mean curvature flow: {res.steps} steps, {res.seconds:.1f} s, areas "
          f"{np.round(res.areas, 3).tolist()}, stopped: {res.stopped}", flush=True)
    view = View(up=(0, 0, 1), front=(1, 0, 0), azim=35.0, elev=25.0)
    extent = framing([m[0] for m in res.meshes], view)
    H_all = np.concatenate([m[2]["H"] for m in res.meshes])
    lo, hi = np.nanpercentile(H_all, [1, 99])
    lim = max(abs(lo), abs(hi))
    n = len(res.meshes)
    fig, axes = plt.subplots(1, n, figsize=(2.5 * n + 1.0, 3.0), layout="constrained")
    cmap, norm = plt.get_cmap("RdBu_r"), Normalize(-lim, lim)
    for ax, (V, F, data), t, A in zip(axes, res.meshes, res.times, res.areas):
        draw_surface(ax, V, F, data["H"], cmap, norm, view, extent)
        ax.set_title(f"t = {t:g}, area {A:.2f}", fontsize=10)
    fig.colorbar(plt.cm.ScalarMappable(norm, cmap), ax=axes, shrink=0.8, pad=0.02,
                 label="mean curvature H")
    fig.suptitle("mean curvature flow $X_t = \\Delta_S X = -2Hn$ of a wobbly ellipsoid "
                 "(one scale and framing)", fontsize=10)
    save(fig, path)
    plt.close(fig)
    return res


# ---------------------------------------------------------------------------- main

def main(argv=None):
    parser = argparse.ArgumentParser(
        prog="gallery.py", description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", "--out-dir", dest="out", default=str(DEFAULT_OUT),
                        help="output folder (default: the project's docs/images)")
    parser.add_argument("--model", help="a fitted spot (.npz) to use instead of fitting")
    parser.add_argument("--mesh", help="fit this mesh instead of "
                                       "../shared/data/meshes/spot_triangulated.obj")
    parser.add_argument("--save-model", help="also save the fitted surface here (.npz)")
    parser.add_argument("--quick", action="store_true",
                        help="a smoke run: a small ellipsoid fit, tiny budgets, coarse meshes "
                             "(seconds); also set by SNS_NP_SMOKE=1")
    parser.add_argument("--seed", type=int, default=0, help="seed of every random choice "
                                                            "(%(default)s)")
    args = parser.parse_args(argv)
    quick = args.quick or SMOKE
    if quick and (args.model or args.mesh):
        parser.error("--quick uses its own small surface; drop --model / --mesh")

    with clear_errors(parser):
        plt = need_matplotlib()
        out = output_dir(args.out)
        out.mkdir(parents=True, exist_ok=True)
        cfg = QUICK if quick else FULL
        t_start = time.perf_counter()
        S, label, view = spot_surface(args, quick)
        print(f"surface ready: {time.perf_counter() - t_start:.0f} s", flush=True)
        figure_mean_curvature(plt, S, label, view, cfg, out / NAMES[0])
        figure_eigenmodes(plt, S, view, cfg, args.seed, out / NAMES[1])
        figure_heat(plt, S, view, cfg, out / NAMES[2])
        figure_mcf(plt, cfg, args.seed, out / NAMES[3])
        print(f"gallery done in {time.perf_counter() - t_start:.0f} s", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
