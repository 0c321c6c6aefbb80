"""Figures of the studies: Fig. 4 / Fig. 9 (path, estimate, variance, transitions), Fig. 5 / Fig. 10 (similarity).

Every figure says what each mark is: axis labels with units, a legend for the marks, a colour bar for the
variance, and the paper's similarity labelled as a ratio of amplitudes that can exceed 1.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

__all__ = ["figure_2d_object", "figure_3d_object", "figure_similarity", "figure_regions", "FRACTION_MARKS",
           "log_axis", "legend_below", "fraction_labels", "Snapshot"]

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


def log_axis(ax, axis: str = "y") -> None:
    """A log-scaled axis with plain numbers on its ticks ("0.5", "1", "2", "5", "10"), no minor-tick labels
    (matplotlib labels minor ticks "2x10^0, 3x10^0" once a range spans less than a decade), and enough major ticks
    to read a value off a range narrower than a decade."""
    from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter

    hi = ax.dataLim.y1 if axis == "y" else ax.dataLim.x1
    if not (np.isfinite(hi) and hi > 0):
        # nothing positive to draw (every run of an object failed before any estimate): a log axis cannot be
        # formed, and the panel says why it is empty
        ax.text(0.5, 0.5, "no estimate in any run", transform=ax.transAxes, ha="center", va="center", fontsize=8)
        return
    a = ax.yaxis if axis == "y" else ax.xaxis
    lo = ax.dataLim.y0 if axis == "y" else ax.dataLim.x0
    lo = lo if np.isfinite(lo) and lo > 0 else hi / 10
    # the ticks that fall inside the data's range: 1-2-5 per decade, or every integer multiple where a narrow range
    # (3.9-4.6 cm) would hold one tick of them or none; a range narrower still stays linear
    for subs in ((1.0, 2.0, 5.0), tuple(float(k) for k in range(1, 10))):
        decades = np.arange(np.floor(np.log10(lo)) - 1, np.ceil(np.log10(hi)) + 1)
        ticks = np.array([m * 10 ** d for d in decades for m in subs])
        if ((ticks >= lo * 0.97) & (ticks <= hi * 1.03)).sum() >= 2:
            break
    else:
        from matplotlib.ticker import MaxNLocator

        a.set_major_locator(MaxNLocator(4))
        return
    (ax.set_yscale if axis == "y" else ax.set_xscale)("log")
    a.set_major_locator(LogLocator(base=10, subs=subs))
    a.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
    a.set_minor_formatter(NullFormatter())


def legend_below(fig, handles, labels, ncol: int = 4, fontsize: float = 7, bottom: float = 0.0):
    """One legend for the whole figure in a strip under every axes (never on top of data)."""
    by_label = dict(zip(labels, handles))
    return fig.legend(list(by_label.values()), list(by_label), loc="lower center", ncol=ncol, fontsize=fontsize,
                      frameon=False, bbox_to_anchor=(0.5, bottom))


def fraction_labels(ax, xs, texts, fontsize: float = 7) -> list:
    """Labels at data x positions above the top of ``ax``, moved up a line where they would overprint a neighbour
    (10, 25 and 50 % of a short run lie close together)."""
    fig = ax.figure
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    placed, out = [], []
    for x, text in sorted(zip(xs, texts)):
        level = 0
        while True:
            t = ax.annotate(text, (x, 1.0), xycoords=("data", "axes fraction"), xytext=(0, 2 + 9 * level),
                            textcoords="offset points", fontsize=fontsize, ha="center", va="bottom", color="0.35")
            box = t.get_window_extent(renderer)
            gap = 0.4 * fontsize * fig.dpi / 72           # labels that merely touch read as one ("10 %25 %")
            padded = box.expanded(1.0 + 2 * gap / max(box.width, 1e-9), 1.0)
            if not any(padded.overlaps(b) for b in placed):
                placed.append(box)
                out.append(t)
                break
            t.remove()
            level += 1
    return out


def _inner_observations(model) -> tuple[np.ndarray, np.ndarray]:
    """`(k, d)` inner contacts (y = 0) and inner free space (y = 1) of a fitted model."""
    x = model.train_inputs[0].cpu().numpy()
    y = model.train_targets.cpu().numpy()
    inner = (model.train_inputs[1].reshape(-1) == 0).cpu().numpy() if len(model.train_inputs) > 1 else \
        np.ones(len(y), bool)
    return x[inner & (y == 0)], x[inner & (y == 1)]


def _transitions(ax_u, ax_h, pair: dict, reference: str = "tactile") -> None:
    """Uncertainty and Hausdorff over travel for both modes; the 10/25/50 % points of the reference run marked. The
    legend entries go to the figure's legend (:func:`legend_below`), never over the curves."""
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
            # the touched pieces only where they differ from the whole zero set: drawn under an equal solid line
            # they were invisible, yet had a legend entry
            whole, touched = tr.hausdorff, tr.hausdorff_touched
            ok = ~np.isnan(touched)
            differs = ok & ~np.isclose(touched, whole, rtol=1e-9, atol=0.0, equal_nan=False)
            if differs.any():
                ax_h.plot(tr.travel[ok], 100 * touched[ok], color=st["color"], ls=":", lw=1.4, zorder=3,
                          label=f"{mode}, touched pieces only (where they differ)")
        for f in FRACTION_MARKS:
            ok = np.flatnonzero(~np.isnan(tr.hausdorff) & (tr.travel >= f * total - 1e-12))
            if len(ok):
                i = ok[0]
                ax_h.plot(tr.travel[i], 100 * tr.hausdorff[i], "o", color=st["color"], ms=5, mfc="white", zorder=4)
    # the markers' legend entry in neutral grey (each mode draws them in its own colour)
    ax_h.plot(
        [], [], "o", color="0.35", ms=5, mfc="white", label="H at 10 / 25 / 50 % of the travel (the maps' moments)"
    )
    for f in FRACTION_MARKS:
        for ax in (ax_u, ax_h):
            ax.axvline(f * total, color="0.75", lw=0.6, zorder=0)
    ax_u.set_ylabel("uncertainty, eq. (23)\n[V / prior variance]")
    log_axis(ax_u)
    ax_h.set_ylabel("Hausdorff distance [cm]")
    for ax in (ax_u, ax_h):                  # the upper panel had none: a reader could not tell what its x axis was
        ax.set_xlabel("travel since first contact [m]")
    log_axis(ax_h)
    fraction_labels(ax_u, [f * total for f in FRACTION_MARKS], [f"{int(f * 100)} %" for f in FRACTION_MARKS])


@dataclass
class Snapshot:
    """The state of a run at one step, for a map: its model, the fingertip's path and the contacts so far.

    Attributes:
        model: the model after the step (rebuilt from the log with the K_t learned then).
        path: `(k, 2)` fingertip positions up to the step [m].
        travel: travel since the first contact [m].
        hausdorff: the step's recorded Hausdorff distance [m] (NaN if not measured).
    """

    model: object
    path: np.ndarray
    travel: float
    hausdorff: float


def _map(ax, scene, model, path: np.ndarray, b: np.ndarray, resolution: float, title: str):
    """One Fig. 4 map: the variance, the true shapes, the estimate (touched pieces solid), the path, the
    observations; returns the image (for the colour bar)."""
    from ..geometry.metrics import prior_variance
    from ..geometry.surfaces import evaluate_grid, touched_pieces, zero_level_curves

    extent = [b[0, 0], b[1, 0], b[0, 1], b[1, 1]]
    f = evaluate_grid(model, b, resolution, 0)
    rel_var = f.var / prior_variance(model, 0)   # fraction of the prior variance: comparable across modes
    im = ax.imshow(rel_var.T, origin="lower", extent=extent, cmap="Purples", vmin=0, vmax=1)
    # a filled shape with a solid outline: the fill alone disappeared into the variance map's purple
    ax.fill(*scene.inner_boundary.T, facecolor="tab:green", alpha=0.35, lw=0)
    ax.fill(*scene.inner_boundary.T, facecolor="none", edgecolor="darkgreen", lw=1.6, zorder=3,
            label="true inner shape")
    ax.plot(*scene.outer_boundary.T, "k-.", lw=1.2, label="outer shape (seen)")
    if len(path):
        ax.plot(*np.asarray(path).T, "-", color="0.35", lw=0.7, label="fingertip path")
    contacts, free = _inner_observations(model)
    curves = zero_level_curves(model, b, resolution, 0, field=f)
    touched = touched_pieces(curves, contacts)
    ids = {id(c) for c in touched}
    for j, c in enumerate(touched):
        ax.plot(*c.T, "-", color="tab:red", lw=1.8, label="estimate $\\mu_{in}=0$ (touched)")
    for c in (c for c in curves if id(c) not in ids):
        ax.plot(*c.T, ":", color="tab:red", lw=1.4, label="untouched pieces of $\\mu_{in}=0$")
    ax.plot(*contacts.T, "o", color="k", ms=2.2, label="contacts ($y=0$)")
    if len(free):
        ax.plot(*free.T, "o", mfc="none", mec="tab:orange", ms=3.5, mew=0.8, label="inner free space ($y=1$)")
    ax.plot(*scene.start, "ks", ms=5, label="start")
    ax.set_aspect("equal")
    ax.set_xlim(extent[:2])
    ax.set_ylim(extent[2:])
    ax.set_title(title, fontsize=8.5)
    ax.set_xlabel("x [m]", fontsize=8)
    ax.set_ylabel("y [m]", fontsize=8)
    ax.tick_params(labelsize=7)
    return im


def _h_text(h: float) -> str:
    return "no closed estimate" if not np.isfinite(h) else f"Hausdorff {100 * h:.1f} cm"


def figure_2d_object(name: str, scene, pair: dict, path: Path, resolution: float = 0.004,
                     early: dict | None = None, early_fraction: float = 0.10):
    """Fig. 4: per mode the variance map, the true shapes, the estimate (touched pieces solid, other pieces of the
    zero set dotted), the path, and the contacts and free space; then the transitions.

    With ``early`` (``{mode: Snapshot}``) a first row shows both modes at ``early_fraction`` of the tactile run's
    travel, where the paper's point ("vision helps early") shows; the second row shows the final state. Every
    legend sits in a strip under the panels, never on the data.

    Returns:
        the ``matplotlib.figure.Figure`` (already written to ``path``).
    """
    plt = _plt()
    rows = 2 if early else 1
    b = scene.bounds(0.08)
    aspect = float((b[1, 1] - b[0, 1]) / (b[1, 0] - b[0, 0]))          # a map's height / width
    fig = plt.figure(figsize=(16, rows * max(4.6 * aspect + 1.3, 3.2) + 1.0))
    # an empty column between the colour bar and the transitions keeps the bar's label clear of their y labels
    grid = fig.add_gridspec(rows * 2, 5, width_ratios=[1.15, 1.15, 0.04, 0.28, 1.0], wspace=0.25, hspace=0.55,
                            left=0.04, right=0.98, top=0.93, bottom=0.11 + 0.03 * (2 - rows))
    im = None
    for k, mode in enumerate(MODES):
        tr = pair.get(mode)
        if tr is None:
            continue
        label = "visual-tactile (GPIOIS)" if mode == "visual-tactile" else "tactile only (GPIS)"
        if early:
            snap = early[mode]
            im = _map(fig.add_subplot(grid[0:2, k]), scene, snap.model, snap.path, b, resolution,
                      f"{name}, {label}: at {int(round(100 * early_fraction))} % of the travel\n"
                      f"({snap.travel:.2f} m, {_h_text(snap.hausdorff)})")
        im = _map(fig.add_subplot(grid[2 * rows - 2:2 * rows, k]), scene, tr.model, tr.path, b, resolution,
                  f"{name}, {label}: final\n({tr.travel[-1]:.2f} m, {tr.n_steps - 1} steps, {tr.terminated}; "
                  f"{_h_text(tr.hausdorff[-1])})")
    if im is not None:
        fig.colorbar(im, cax=fig.add_subplot(grid[:, 2]), label="$V_{in}$ / prior variance")
    ax_u = fig.add_subplot(grid[0:rows, 4])
    ax_h = fig.add_subplot(grid[rows:2 * rows, 4], sharex=ax_u)
    _transitions(ax_u, ax_h, pair)
    handles, labels = [], []
    for ax in fig.axes:
        h, lab = ax.get_legend_handles_labels()
        handles += h
        labels += lab
    legend_below(fig, handles, labels, ncol=6)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return fig


def figure_3d_object(name: str, scene, pair: dict, path: Path) -> None:
    """Fig. 9: per mode, a large panel of the final estimate in the exploration range coloured by its posterior
    variance (a colour map whose certain end is a bright magenta, not the dark end that hid it in the wire), the
    true inner surface as a green wire, the cover the camera saw as a pale skin, the path and the contacts; below,
    the colour bar and the transitions."""
    import torch
    from matplotlib import cm, colors
    from matplotlib.colors import LinearSegmentedColormap
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    from ..geometry.differential import predict_task
    from ..geometry.metrics import prior_variance
    from ..geometry.surfaces import clip_mesh

    plt = _plt()
    fig = plt.figure(figsize=(13, 11))
    grid = fig.add_gridspec(2, 2, height_ratios=[2.4, 1.0], hspace=0.2, wspace=0.0)
    norm = colors.Normalize(0.0, 1.0)
    cmap = LinearSegmentedColormap.from_list("plasma_bright", plt.get_cmap("plasma")(np.linspace(0.3, 0.95, 64)))
    lo, hi = scene.range[0], scene.range[1]
    truth = clip_mesh(scene.inner, lo, hi)
    cover = clip_mesh(scene.outer, lo, hi) if getattr(scene, "outer", None) is not None else None
    for j, mode in enumerate(MODES):
        ax = fig.add_subplot(grid[0, j], projection="3d")
        tr = pair.get(mode)
        if tr is None:
            continue
        mesh = tr.final_mesh
        if cover is not None:
            tri = cover.triangles[:: max(1, len(cover.triangles) // 1500)]
            ax.add_collection3d(Poly3DCollection(tri, facecolors=(0.45, 0.65, 0.95, 0.12), edgecolors="none"))
        if truth is not None:
            tri = truth.triangles[:: max(1, len(truth.triangles) // 1500)]
            ax.add_collection3d(Poly3DCollection(tri, facecolors="none", edgecolors=(0.1, 0.55, 0.2, 0.45),
                                                 linewidths=0.2))
        if mesh is not None:
            x0 = tr.model.train_inputs[0]
            with torch.no_grad():
                _, var = predict_task(tr.model, torch.as_tensor(np.array(mesh.triangles_center), dtype=x0.dtype), 0)
            rel = var.cpu().numpy() / prior_variance(tr.model, 0)
            ax.add_collection3d(Poly3DCollection(mesh.triangles, facecolors=cmap(norm(rel)), edgecolor="none",
                                                 alpha=0.85))
        ax.plot(*tr.path.T, "-", color="tab:orange", lw=1)
        ax.scatter(*tr.contacts.T, s=3, c="k")
        ax.scatter(*tr.contacts[0], s=30, c="red", marker="*")
        ax.set_xlim(lo[0], hi[0])
        ax.set_ylim(lo[1], hi[1])
        ax.set_zlim(lo[2], hi[2])
        ax.set_box_aspect(hi - lo, zoom=1.15)          # the panel's box fills its cell
        ax.set_xlabel("x [m]", fontsize=8, labelpad=2)
        ax.set_ylabel("y [m]", fontsize=8, labelpad=2)
        ax.set_zlabel("z [m]", fontsize=8, labelpad=0)
        ax.tick_params(labelsize=7, pad=0)
        from matplotlib.ticker import MaxNLocator

        for axis in (ax.xaxis, ax.yaxis, ax.zaxis):          # ten ticks a side ran their labels together
            axis.set_major_locator(MaxNLocator(4))
        final = ("no estimate: no surface in the range" if tr.has_estimate is False or np.isnan(tr.hausdorff[-1])
                 else f"final Hausdorff {100 * tr.hausdorff[-1]:.1f} cm")
        ax.set_title(f"{name}: {mode}\n{final}", fontsize=10)
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    handles = [Line2D([], [], color="tab:orange", label="fingertip path"),
               Line2D([], [], ls="", marker="o", ms=2, color="k", label="contacts"),
               Line2D([], [], ls="", marker="*", ms=6, color="red", label="first contact"),
               Patch(facecolor="none", edgecolor=(0.1, 0.55, 0.2), label="true inner surface (green wire)"),
               Patch(facecolor=(0.55, 0.7, 0.9, 0.3), label="cover (outer surface)"),
               Patch(facecolor=cmap(0.3), label="estimate $\\mu_{in}=0$, coloured by $V_{in}$")]
    bottom = grid[1, :].subgridspec(1, 5, width_ratios=[0.04, 0.05, 0.12, 1, 1], wspace=0.3)
    cax = fig.add_subplot(bottom[0, 1])
    fig.colorbar(cm.ScalarMappable(norm=norm, cmap=cmap), cax=cax, label="$V_{in}$ / prior variance on the estimate")
    ax_u = fig.add_subplot(bottom[0, 3])
    ax_h = fig.add_subplot(bottom[0, 4], sharex=ax_u)
    _transitions(ax_u, ax_h, pair)
    h, lab = ax_h.get_legend_handles_labels()
    fig.subplots_adjust(left=0.01, right=0.99, top=0.95, bottom=0.12)
    legend_below(fig, handles + h, [x.get_label() for x in handles] + lab, ncol=4)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return fig


def figure_similarity(traces: dict, path: Path, title: str = "Similarity transitions (cf. Fig. 5)"):
    """Fig. 5 / Fig. 10 for single runs, one column per object (four overlapping interval bands merged into one
    grey-brown mass): top the task correlation with its 95 % profile-likelihood interval where it was computed,
    bottom the paper's similarity ``K_t[0,1] / K_t[0,0]`` (a ratio of amplitudes, not a correlation: it can exceed
    1).

    Returns:
        the ``matplotlib.figure.Figure`` (already written to ``path``).
    """
    plt = _plt()
    names = [n for n, pair in traces.items() if pair.get("visual-tactile") is not None]
    cols = max(len(names), 1)
    fig, axes = plt.subplots(2, cols, figsize=(3.3 * cols + 0.8, 6.2), squeeze=False, sharey="row")
    for i, name in enumerate(names):
        tr = traces[name]["visual-tactile"]
        ax_c, ax_s = axes[0, i], axes[1, i]
        color = f"C{i}"
        ci = tr.correlation_interval
        if len(ci) and np.isfinite(ci).any():
            ok = np.isfinite(ci).all(axis=1)
            ax_c.fill_between(tr.travel[ok], ci[ok, 0], ci[ok, 1], color=color, alpha=0.25, lw=0,
                              label="95 % profile-likelihood interval")
        if len(tr.correlation):
            ax_c.plot(tr.travel, tr.correlation, color=color, label="correlation")
        ax_s.plot(tr.travel, tr.similarity, color=color, label="paper's ratio")
        ax_s.axhline(1.0, color="0.6", lw=0.6, ls="--")
        ax_s.axhline(0.0, color="k", lw=0.5)
        ax_c.set(title=f"object {name}", ylim=(-1.05, 1.05))
        ax_s.set_xlabel("travel since first contact [m]", fontsize=8)
        for ax in (ax_c, ax_s):
            ax.tick_params(labelsize=7)
    axes[0, 0].set_ylabel("task correlation\n$K_t[0,1]/\\sqrt{K_t[0,0]K_t[1,1]}$", fontsize=8)
    axes[1, 0].set_ylabel("paper's similarity $K_t[0,1]/K_t[0,0]$\n(a ratio: can exceed 1)", fontsize=8)
    import textwrap

    # one object leaves a narrow figure: the title wraps and the legend stacks, instead of running off both edges
    width = fig.get_size_inches()[0]
    fig.suptitle(textwrap.fill(title + ": the correlation with its interval (top), the paper's ratio (bottom)",
                               int(width * 10.5)), fontsize=10)
    ncol = 3 if cols > 1 else 1
    fig.tight_layout(rect=(0, 0.06 if ncol == 3 else 0.11, 1, 1))
    from matplotlib.patches import Patch

    # neutral handles: each object has its own colour, and the dashed line is the reference 1 (the legend showed
    # the first object's colour for every curve and a solid line for the dashed one)
    handles = [Patch(facecolor="0.5", alpha=0.3, label="95 % profile-likelihood interval (object's colour)"),
               plt.Line2D([], [], color="0.3", label="correlation (top) / paper's ratio (bottom), object's colour"),
               plt.Line2D([], [], color="0.6", lw=0.6, ls="--", label="ratio 1 (reference)")]
    legend_below(fig, handles, [h.get_label() for h in handles], ncol=ncol)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return fig


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
