"""Fit GPIOIS on an inner and an outer 2-D shape and plot the mu_in = 0 curve over the variance map.

Two pairs from the paper's objects: A (outer = inner grown by 4.5 cm: similar) and D (a 20 x 15 cm inner in an
80 x 60 cm outer: dissimilar). The inner shape is "touched" on its left half only; the outer is "seen" all round.
For each pair the script learns K_t with four observation sets and prints the similarity K_t[0,1]/K_t[0,0]:

  surface only        inner contacts + outer boundary (all y = 0)
  + outer free space  + camera free space 5 cm outside the outer boundary (y = 1, outer task)
  + inner free space  + free space the toucher occupied on its approach, >= 2 cm from contacts (y = 1, inner)
  both                all of the above (what the exploration uses)

Run:  python examples/fit_two_shapes.py [--out DIR]   (about 10 s; CI=1 makes it smaller)
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import torch_gpioius as tg  # noqa: E402
from torch_gpioius.exploration import free_space_along, thin_points  # noqa: E402

SMOKE = "CI" in os.environ


def observations(scene, inner_free: bool, outer_free: bool, spacing: float):
    touched = scene.sample_boundary("inner", 0.01)
    touched = touched[touched[:, 0] <= scene.inner.centroid.x]                 # left half touched
    x = [touched]
    y = [np.zeros(len(touched))]
    t = [np.zeros(len(touched), dtype=int)]
    if inner_free:
        contact = scene.first_contact()
        # the approach path, sampled every 2 cm and kept 2 cm from every contact (the exploration's rule)
        free = thin_points(free_space_along(scene.start, contact, 0.02), 0.02, touched, 0.02)
        x.append(free), y.append(np.ones(len(free))), t.append(np.zeros(len(free), dtype=int))
    seen = scene.sample_boundary("outer", spacing)
    x.append(seen), y.append(np.zeros(len(seen))), t.append(np.ones(len(seen), dtype=int))
    if outer_free:
        ring = scene.sample_offset("outer", 0.05, spacing)
        x.append(ring), y.append(np.ones(len(ring))), t.append(np.ones(len(ring), dtype=int))
    return np.concatenate(x), np.concatenate(y), np.concatenate(t)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="outputs/fit_two_shapes")
    args = parser.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    spacing = 0.04 if SMOKE else 0.02
    objects = tg.sim.paper_objects_2d()
    settings = {"surface only": (False, False), "+ outer free space": (False, True),
                "+ inner free space": (True, False), "both": (True, True)}
    print(f"{'pair':<16}" + "".join(f"{k:>22}" for k in settings))
    fig, axes = plt.subplots(1, 2, figsize=(12, 5))
    for ax, (label, name) in zip(axes, [("A (similar)", "A"), ("D (dissimilar)", "D")]):
        scene = objects[name]
        sims = []
        for key, (inner_free, outer_free) in settings.items():
            x, y, t = observations(scene, inner_free, outer_free, spacing)
            model = tg.GPIOIS(x, y, t, kernel=tg.InverseMultiquadricKernel(0.1), noise=0.006).fit()
            sims.append(f"{model.similarity:8.3f} (rho {model.correlation:4.2f})")
        print(f"{label:<16}" + "".join(f"{s:>22}" for s in sims))
        bounds = scene.bounds(0.08)                       # (2, 2): [min corner; max corner]
        field = tg.surfaces.evaluate_grid(model, bounds, 0.005, task=0)
        extent = [bounds[0, 0], bounds[1, 0], bounds[0, 1], bounds[1, 1]]
        prior = tg.metrics.prior_variance(model, 0)
        im = ax.imshow(field.var.T / prior, origin="lower", extent=extent, cmap="Purples", vmin=0, vmax=1)
        ax.fill(*scene.inner_boundary.T, color="tab:green", alpha=0.3, label="true inner")
        ax.plot(*scene.outer_boundary.T, "k-.", label="outer")
        for j, c in enumerate(tg.surfaces.zero_level_curves(model, bounds, 0.005, field=field)):
            ax.plot(*c.T, "r", label="$\\mu_{in} = 0$" if j == 0 else None)
        inner = t == 0
        ax.plot(*x[inner & (y == 0)].T, "k.", ms=3, label="contacts")
        ax.plot(*x[inner & (y == 1)].T, "bx", ms=4, label="inner free space")
        ax.set_title(f"{label}, all observations: correlation {model.correlation:.2f}\n"
                     f"(the paper's similarity K01/K00 = {model.similarity:.2f})", fontsize=9)
        ax.set(xlabel="x [m]", ylabel="y [m]", aspect="equal")
        ax.legend(fontsize=7, loc="lower right")
        fig.colorbar(im, ax=ax, fraction=0.04, label="$V_{in}$ / prior variance")
    fig.tight_layout()
    fig.savefig(out / "fit_two_shapes.png", dpi=110)
    print(f"figure: {out / 'fit_two_shapes.png'}")


if __name__ == "__main__":
    main()
