"""Figures of the studies: Fig. 4 / Fig. 9 (path, estimate, variance, transitions), Fig. 5 / Fig. 10 (similarity).

Every figure says what each mark is: axis labels with units, a legend for the marks, a colour bar for the
variance, and the paper's similarity labelled as a ratio of amplitudes that can exceed 1.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

__all__ = ["figure_2d_object", "figure_3d_object", "figure_similarity", "figure_regions", "FRACTION_MARKS"]

MODES = ("visual-tactile", "tactile")
STYLE = {"visual-tactile": dict(color="tab:red", ls="-"), "tactile": dict(color="tab:blue", ls="--")}
#: Fractions of the tactile run's travel marked on the transition curves (the table's columns).
FRACTION_MARKS = (0.10, 0.25, 0.50)


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _at_travel(trace, distance: float) -> int:
    return int(min(np.searchsorted(trace.travel, distance - 1e-12), trace.n_steps - 1))


def _inner_observations(model) -> tuple[np.ndarray, np.ndarray]:
    """`(k, d)` inner contacts (y = 0) and inner free space (y = 1) of a fitted model."""
    x = model.train_inputs[0].cpu().numpy()
    y = model.train_targets.cpu().numpy()
    inner = (model.train_inputs[1].reshape(-1) == 0).cpu().numpy() if len(model.train_inputs) > 1 else \
        np.ones(len(y), bool)
    return x[inner & (y == 0)], x[inner & (y == 1)]


def _transitions(ax_u, ax_h, pair: dict, reference: str = "tactile") -> None:
    """Uncertainty and Hausdorff over travel for both modes; the 10/25/50 % points of the reference run marked."""
    ref = pair.get(reference) or next(iter(pair.values()))
    total = float(ref.travel[-1])
    for mode in MODES:
        tr = pair.get(mode)
        if tr is None:
            continue
        st = STYLE[mode]
        for ax, y, scale in ((ax_u, tr.uncertainty, 1.0), (ax_h, tr.hausdorff, 100.0)):
            ok = ~np.isnan(y)
            ax.plot(tr.travel[ok], scale * y[ok], label=mode, **st)
        if len(tr.hausdorff_touched):
            ok = ~np.isnan(tr.hausdorff_touched)
            ax_h.plot(tr.travel[ok], 100 * tr.hausdorff_touched[ok], color=st["color"], ls=":", lw=1,
                      label=f"{mode}, touched pieces")
        for f in FRACTION_MARKS:
            ok = np.flatnonzero(~np.isnan(tr.hausdorff) & (tr.travel >= f * total - 1e-12))
            if len(ok):
                i = ok[0]
                ax_h.plot(tr.travel[i], 100 * tr.hausdorff[i], "o", color=st["color"], ms=5, mfc="white")
    for f in FRACTION_MARKS:
        for ax in (ax_u, ax_h):
            ax.axvline(f * total, color="0.75", lw=0.6, zorder=0)
        ax_h.annotate(f"{int(f * 100)} %", (f * total, 1.0), xycoords=("data", "axes fraction"), fontsize=7,
                      ha="center", va="bottom", color="0.4")
    ax_u.set_ylabel("uncertainty, eq. (23)\n[V / prior variance]")
    ax_u.set_yscale("log")
    ax_u.legend(fontsize=7)
    ax_h.set_ylabel("Hausdorff distance [cm]")
    ax_h.set_xlabel("travel since first contact [m]")
    ax_h.set_yscale("log")
    ax_h.legend(fontsize=6, loc="upper right")


def figure_2d_object(name: str, scene, pair: dict, path: Path, resolution: float = 0.004) -> None:
    """Fig. 4: per mode the variance map, the true shapes, the estimate (touched pieces solid, other pieces of the
    zero set dotted), the path, and the contacts and free space as markers on top; then the transitions."""
    from ..metrics import prior_variance
    from ..surfaces import evaluate_grid, touched_pieces, zero_level_curves

    plt = _plt()
    fig = plt.figure(figsize=(15, 5.2))
    grid = fig.add_gridspec(2, 3, width_ratios=[1.15, 1.15, 1.0])
    b = scene.bounds(0.08)
    extent = [b[0, 0], b[1, 0], b[0, 1], b[1, 1]]
    for k, mode in enumerate(MODES):
        ax = fig.add_subplot(grid[:, k])
        tr = pair.get(mode)
        if tr is None:
            continue
        f = evaluate_grid(tr.model, b, resolution, 0)
        rel_var = f.var / prior_variance(tr.model, 0)   # fraction of the prior variance: comparable across modes
        im = ax.imshow(rel_var.T, origin="lower", extent=extent, cmap="Purples", vmin=0, vmax=1)
        ax.fill(*scene.inner_boundary.T, color="tab:green", alpha=0.35, lw=0, label="true inner shape")
        ax.plot(*scene.outer_boundary.T, "k-.", lw=1.2, label="outer shape (seen)")
        ax.plot(*tr.path.T, "-", color="0.35", lw=0.7, label="fingertip path")
        curves = zero_level_curves(tr.model, b, resolution, 0, field=f)
        touched = touched_pieces(curves, tr.contacts)
        ids = {id(c) for c in touched}
        for j, c in enumerate(touched):
            ax.plot(*c.T, "-", color="tab:red", lw=1.8, label="estimate $\\mu_{in}=0$ (touched)" if j == 0 else None)
        others = [c for c in curves if id(c) not in ids]
        for j, c in enumerate(others):
            ax.plot(*c.T, ":", color="tab:red", lw=1.4, label="untouched pieces of $\\mu_{in}=0$" if j == 0 else None)
        contacts, free = _inner_observations(tr.model)
        ax.plot(*contacts.T, "o", color="k", ms=2.2, label="contacts ($y=0$)")
        if len(free):
            ax.plot(*free.T, "o", mfc="none", mec="tab:orange", ms=3.5, mew=0.8, label="inner free space ($y=1$)")
        ax.plot(*scene.start, "ks", ms=5, label="start")
        ax.set_aspect("equal")
        ax.set_xlim(extent[:2])
        ax.set_ylim(extent[2:])
        title = "visual-tactile (GPIOIS)" if mode == "visual-tactile" else "tactile only (GPIS)"
        ax.set_title(f"object {name}: {title}\nfinal Hausdorff {100 * tr.hausdorff[-1]:.1f} cm, {tr.n_steps - 1} "
                     f"steps ({tr.terminated})", fontsize=9)
        ax.set_xlabel("x [m]")
        ax.set_ylabel("y [m]")
        if k == 0:
            ax.legend(loc="lower left", fontsize=6, framealpha=0.85)
        fig.colorbar(im, ax=ax, fraction=0.035, label="$V_{in}$ / prior variance")
    ax_u = fig.add_subplot(grid[0, 2])
    ax_h = fig.add_subplot(grid[1, 2], sharex=ax_u)
    _transitions(ax_u, ax_h, pair)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def figure_3d_object(name: str, scene, pair: dict, path: Path) -> None:
    """Fig. 9: per mode the final estimate in the exploration range coloured by its posterior variance (with a
    colour bar), the true inner surface as a grey wire, the path and the contacts; then the transitions."""
    import torch
    from matplotlib import cm, colors
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    from ..geometry import predict_task
    from ..metrics import prior_variance
    from ..surfaces import clip_mesh

    plt = _plt()
    fig = plt.figure(figsize=(17, 5.2))
    # an empty column between the colour bar and the transitions keeps the bar's label clear of their y labels
    grid = fig.add_gridspec(2, 5, width_ratios=[1.25, 1.25, 0.06, 0.3, 1.1], wspace=0.35)
    norm = colors.Normalize(0.0, 1.0)
    cmap = plt.get_cmap("viridis")
    lo, hi = scene.range[0], scene.range[1]
    truth = clip_mesh(scene.inner, lo, hi)
    for j, mode in enumerate(MODES):
        ax = fig.add_subplot(grid[:, j], projection="3d")
        tr = pair.get(mode)
        if tr is None:
            continue
        mesh = tr.final_mesh
        if truth is not None:
            tri = truth.triangles[:: max(1, len(truth.triangles) // 1500)]
            ax.add_collection3d(Poly3DCollection(tri, facecolors="none", edgecolors="0.55", linewidths=0.15))
        if mesh is not None:
            x0 = tr.model.train_inputs[0]
            with torch.no_grad():
                _, var = predict_task(tr.model, torch.as_tensor(np.array(mesh.triangles_center), dtype=x0.dtype), 0)
            rel = var.numpy() / prior_variance(tr.model, 0)
            ax.add_collection3d(Poly3DCollection(mesh.triangles, facecolors=cmap(norm(rel)), edgecolor="none",
                                                 alpha=0.8))
        ax.plot(*tr.path.T, "-", color="tab:orange", lw=1, label="fingertip path")
        ax.scatter(*tr.contacts.T, s=2, c="k", label="contacts")
        ax.scatter(*tr.contacts[0], s=25, c="red", marker="*", label="first contact")
        ax.set_xlim(lo[0], hi[0])
        ax.set_ylim(lo[1], hi[1])
        ax.set_zlim(lo[2], hi[2])
        ax.set_box_aspect(hi - lo)
        ax.set_xlabel("x [m]", fontsize=7, labelpad=2)
        ax.set_ylabel("y [m]", fontsize=7, labelpad=2)
        ax.set_zlabel("z [m]", fontsize=7, labelpad=0)
        ax.tick_params(labelsize=6, pad=0)
        ax.set_title(f"{name}: {mode}\nfinal Hausdorff {100 * tr.hausdorff[-1]:.1f} cm", fontsize=9)
        if j == 0:
            from matplotlib.lines import Line2D
            from matplotlib.patches import Patch

            handles = [Line2D([], [], color="tab:orange", label="fingertip path"),
                       Line2D([], [], ls="", marker="o", ms=2, color="k", label="contacts"),
                       Patch(facecolor="none", edgecolor="0.55", label="true inner surface (wire)"),
                       Patch(facecolor=cmap(0.6), label="estimate $\\mu_{in}=0$, coloured by $V_{in}$")]
            ax.legend(handles=handles, fontsize=6, loc="upper left")
    cax = fig.add_subplot(grid[:, 2])
    fig.colorbar(cm.ScalarMappable(norm=norm, cmap=cmap), cax=cax, label="$V_{in}$ / prior variance on the estimate")
    ax_u = fig.add_subplot(grid[0, 4])
    ax_h = fig.add_subplot(grid[1, 4], sharex=ax_u)
    _transitions(ax_u, ax_h, pair)
    fig.subplots_adjust(left=0.02, right=0.98, top=0.9, bottom=0.1)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def figure_similarity(traces: dict, path: Path, title: str = "Similarity transitions (cf. Fig. 5)") -> None:
    """Fig. 5 / Fig. 10 for single runs: left the task correlation (with its profile-likelihood interval where it
    was computed), right the paper's similarity ``K_t[0,1] / K_t[0,0]``: a ratio of amplitudes, not a
    correlation, which can exceed 1."""
    plt = _plt()
    fig, (ax_c, ax_s) = plt.subplots(1, 2, figsize=(11, 4))
    for i, (name, pair) in enumerate(traces.items()):
        tr = pair.get("visual-tactile")
        if tr is None:
            continue
        color = f"C{i}"
        if len(tr.correlation):
            ax_c.plot(tr.travel, tr.correlation, color=color, label=f"object {name}")
            ci = tr.correlation_interval
            if len(ci) and np.isfinite(ci).any():
                ok = np.isfinite(ci).all(axis=1)
                ax_c.fill_between(tr.travel[ok], ci[ok, 0], ci[ok, 1], color=color, alpha=0.2, lw=0)
        ax_s.plot(tr.travel, tr.similarity, color=color, label=f"object {name}")
    ax_c.set(xlabel="travel since first contact [m]", ylabel="correlation $K_t[0,1]/\\sqrt{K_t[0,0]K_t[1,1]}$",
             ylim=(-1.05, 1.05), title="task correlation (band: 95 % profile-likelihood interval)")
    ax_s.axhline(1.0, color="0.6", lw=0.6, ls="--")
    ax_s.axhline(0.0, color="k", lw=0.5)
    ax_s.set(xlabel="travel since first contact [m]", ylabel="paper's similarity $K_t[0,1]/K_t[0,0]$",
             title="the paper's similarity (a ratio of amplitudes: can exceed 1)")
    for ax in (ax_c, ax_s):
        ax.legend(fontsize=7)
        ax.title.set_fontsize(9)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def figure_regions(trace, path: Path, title: str = "") -> None:
    """The local model's similarity per region: the seen outer surface coloured by the local correlation there
    (``LocalGPIOIS.correlation_at``), the contacts, the region centres with their final correlations, and each
    region's correlation over the travel.

    Args:
        trace: a :class:`torch_gpioius.Trace` of a run with ``regions=R`` (its ``model`` is a ``LocalGPIOIS``).
        path: output PNG.
        title: figure title.
    """
    import torch

    plt = _plt()
    model = trace.model
    if not hasattr(model, "correlation_at"):
        raise ValueError("figure_regions: the run has no similarity per region (explore(..., regions=R))")
    x = model.train_inputs[0].cpu().numpy()
    y = model.train_targets.cpu().numpy()
    task = model.train_inputs[1].reshape(-1).cpu().numpy()
    seen = x[(task == 1) & (y == 0)]
    rho = model.correlation_at(torch.as_tensor(seen)).cpu().numpy()
    contacts, _ = _inner_observations(model)
    centres = model.centres.cpu().numpy()
    final = model.region_correlations().cpu().numpy()
    dim = x.shape[1]
    fig = plt.figure(figsize=(12, 4.8))
    ax = fig.add_subplot(1, 2, 1, projection="3d" if dim == 3 else None)
    sc = ax.scatter(*seen.T, c=rho, cmap="coolwarm_r", vmin=-1, vmax=1, s=10, label="seen outer surface")
    ax.scatter(*contacts.T, c="k", s=6, label="contacts")
    for r, (c, v) in enumerate(zip(centres, final)):
        ax.scatter(*c, marker="X", s=90, c=[v], cmap="coolwarm_r", vmin=-1, vmax=1, edgecolors="k")
        ax.text(*c, f" {r}: {v:.2f}", fontsize=8)
    fig.colorbar(sc, ax=ax, label="local task correlation at the seen surface", shrink=0.8)
    ax.set(xlabel="x [m]", ylabel="y [m]", title="similarity by region (X: region centres)")
    if dim == 3:
        ax.set_zlabel("z [m]")
    else:
        ax.set_aspect("equal")
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.14), ncol=2, fontsize=8)
    ax2 = fig.add_subplot(1, 2, 2)
    rc = np.asarray(trace.region_correlation)
    for r in range(rc.shape[1]):
        ax2.plot(trace.travel, rc[:, r], label=f"region {r}")
    ax2.set(xlabel="travel since first contact [m]", ylabel="task correlation of the region", ylim=(-1.05, 1.05),
            title="region correlations over the run")
    ax2.legend(fontsize=8)
    fig.suptitle(title)
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
