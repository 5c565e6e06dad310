"""Render the mean and Gaussian curvature of a fitted neural surface to a PNG.

What it shows: a fitted surface is a smooth map S from the unit sphere, so its curvature is
computed exactly from derivatives of the network at any point, with no mesh in between. The
figure has three panels:

  1. the surface in 3-D (S evaluated on an icosphere), coloured by the mean curvature H;
  2. H on an equirectangular map of the sphere (longitude across, latitude up), i.e. over the
     surface's own parameter domain;
  3. the Gaussian curvature K on the same map (red: K > 0, elliptic; blue: K < 0, saddle).

Colour limits are the 2nd and 98th percentiles, so a few extreme values (at sharp features, or
on a barely trained surface) do not wash out the rest.

Run (from the project root):

    python examples/curvature_map.py                       # a built-in surface, see below
    python examples/curvature_map.py sns_np_examples_out/spot_triangulated.npz --level 6
    python examples/curvature_map.py --help

With no model named, it uses OUT_DIR/ellipsoid.npz when examples/fit_mesh.py has written it;
otherwise it fits a small network (64 x 2, 400 steps: a few seconds) to the built-in ellipsoid
(semi-axes 1, 1.3, 0.7) by itself, saves it as OUT_DIR/ellipsoid_small.npz and renders that.

Output: OUT_DIR/<model name>_curvature.png (OUT_DIR defaults to ./sns_np_examples_out).
"""

import argparse
import sys
from pathlib import Path

import numpy as np
from _common import DEFAULT_OUT_DIR, SMOKE, clear_errors, output_dir, positive_int, write_atomically

from sns_np.geometry import differential_quantities
from sns_np.shapes import Ellipsoid
from sns_np.surface import SphericalNeuralSurface, fit_shape

#: the built-in surface's fit: small enough for seconds, accurate to a fraction of a degree
SMALL_FIT = dict(width=32, depth=2, steps=50, batch=512) if SMOKE else \
    dict(width=64, depth=2, steps=400, batch=1024)


def builtin_surface(out_dir):
    """Fit the built-in ellipsoid with a small network, save it, return (surface, path)."""
    path = out_dir / "ellipsoid_small.npz"
    print(f"no model given and no {out_dir / 'ellipsoid.npz'}: fitting a small network "
          f"({SMALL_FIT['width']} x {SMALL_FIT['depth']}, {SMALL_FIT['steps']} steps) to the "
          f"built-in ellipsoid (1, 1.3, 0.7)")
    surface, report = fit_shape(Ellipsoid(1.0, 1.3, 0.7), seed=0, progress=False, **SMALL_FIT)
    print(report.summary())
    out_dir.mkdir(parents=True, exist_ok=True)
    surface.save(path)
    print(f"saved {path}")
    return surface, path


def equirectangular_points(width):
    """Unit vectors at the pixel centres of a (width // 2, width) longitude-latitude grid."""
    height = width // 2
    lon = np.linspace(-np.pi, np.pi, width, endpoint=False) + np.pi / width
    lat = np.linspace(np.pi / 2, -np.pi / 2, height, endpoint=False) - np.pi / (2 * height)
    lon, lat = np.meshgrid(lon, lat)                        # row 0 is the north pole's row
    p = np.stack([np.cos(lat) * np.cos(lon), np.cos(lat) * np.sin(lon), np.sin(lat)], axis=-1)
    return p.reshape(-1, 3), (height, width)


def robust_limits(values, symmetric=False):
    """The 2nd and 98th percentiles of the finite values (symmetric about 0 if asked)."""
    lo, hi = np.nanpercentile(values, [2, 98])
    if symmetric:
        lo, hi = -max(abs(lo), abs(hi)), max(abs(lo), abs(hi))
    return (lo, hi) if hi > lo else (lo - 1, hi + 1)


def render(surface, level, map_width, path):
    try:
        import matplotlib
    except ImportError:
        raise ImportError("this example needs matplotlib: pip install 'sns-np[plots]'") from None
    matplotlib.use("Agg")                                   # files only, no window
    import matplotlib.pyplot as plt
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    V, F, data = surface.to_mesh(level)                     # points and fields at the vertices
    p, shape = equirectangular_points(map_width)
    dq = differential_quantities(surface, p, on_degenerate="nan")
    H_map, K_map = dq.H.reshape(shape), dq.K.reshape(shape)
    H_lo, H_hi = robust_limits(np.concatenate([data["H"], dq.H]))
    K_lim = robust_limits(dq.K, symmetric=True)

    fig = plt.figure(figsize=(15, 4.6))
    ax = fig.add_subplot(1, 3, 1, projection="3d")
    H_face = np.nanmean(data["H"][F], axis=1)               # one colour per triangle
    faces = Poly3DCollection(V[F], array=H_face, cmap="viridis", clim=(H_lo, H_hi),
                             linewidth=0, antialiased=False)   # no seams between triangles
    ax.add_collection3d(faces)
    lo, hi = V.min(axis=0), V.max(axis=0)
    ax.set(xlim=(lo[0], hi[0]), ylim=(lo[1], hi[1]), zlim=(lo[2], hi[2]),
           xlabel="x", ylabel="y", zlabel="z", title="surface coloured by H")
    ax.set_box_aspect(hi - lo)                              # true proportions
    ax.locator_params(nbins=4)
    fig.colorbar(faces, ax=ax, shrink=0.7, label="H")

    extent = (-180, 180, -90, 90)
    for i, (values, title, cmap, (vmin, vmax)) in enumerate([
            (H_map, "mean curvature H", "viridis", (H_lo, H_hi)),
            (K_map, "Gaussian curvature K", "RdBu_r", K_lim)], start=2):
        ax = fig.add_subplot(1, 3, i)
        image = ax.imshow(values, extent=extent, cmap=cmap, vmin=vmin, vmax=vmax)
        ax.set(title=f"{title} over the sphere", xlabel="longitude (deg)",
               ylabel="latitude (deg)", xticks=range(-180, 181, 90), yticks=range(-90, 91, 45))
        fig.colorbar(image, ax=ax, shrink=0.7)
    fig.suptitle(f"{path.stem}: H in [{np.nanmin(dq.H):.3g}, {np.nanmax(dq.H):.3g}], "
                 f"K in [{np.nanmin(dq.K):.3g}, {np.nanmax(dq.K):.3g}] (units of the mesh)")
    fig.tight_layout()
    write_atomically(path, lambda tmp: fig.savefig(tmp, dpi=110, format="png"))
    plt.close(fig)
    return dq


def main(argv=None):
    parser = argparse.ArgumentParser(
        prog="curvature_map.py", description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("model", nargs="?", default=None,
                        help="fitted model (.npz); default: OUT_DIR/ellipsoid.npz, written by "
                             "examples/fit_mesh.py, or else a small fit of the built-in "
                             "ellipsoid made on the spot")
    parser.add_argument("--out-dir", default=DEFAULT_OUT_DIR, help="output folder (%(default)s)")
    parser.add_argument("--level", type=int, default=3 if SMOKE else 5,
                        help="icosphere level of the 3-D view, 0..7 (%(default)s)")
    parser.add_argument("--map-width", type=positive_int, default=90 if SMOKE else 240,
                        help="pixels across the sphere maps (%(default)s)")
    args = parser.parse_args(argv)
    if not 0 <= args.level <= 7:
        parser.error(f"--level must be between 0 and 7, got {args.level}")

    with clear_errors(parser):
        out_dir = output_dir(args.out_dir)
        model = Path(args.model) if args.model else out_dir / "ellipsoid.npz"
        if args.model is None and not model.exists():
            surface, model = builtin_surface(out_dir)
        else:
            surface = SphericalNeuralSurface.load(model)    # names the problem if it fails
        path = out_dir / f"{model.stem}_curvature.png"
        dq = render(surface, args.level, args.map_width, path)
        print(f"{model}: mean curvature H in [{np.nanmin(dq.H):.4g}, {np.nanmax(dq.H):.4g}], "
              f"Gaussian curvature K in [{np.nanmin(dq.K):.4g}, {np.nanmax(dq.K):.4g}]")
        print(f"saved {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
