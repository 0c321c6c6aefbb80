"""Figures of a sweep over seeds: transitions as median lines with bands, the similarity as bands, and the paired
final Hausdorff distances per seed."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .figures import legend_below, log_axis

__all__ = ["figure_transition_bands", "figure_similarity_bands", "figure_paired"]

COLORS = {"visual-tactile": "tab:red", "tactile": "tab:blue", "visual-tactile+taps": "tab:purple",
          "local": "tab:orange", "local+taps": "tab:brown",
          "visual-tactile+reach": "tab:green", "tactile+reach": "tab:cyan"}


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _on_grid(run: dict, key: str, grid: np.ndarray) -> np.ndarray:
    """A run's measured values of ``key`` as a step function of travel on ``grid``; after its end the last value
    stays (the estimate does not change once the run has stopped); NaN before its first measurement."""
    t = np.asarray(run["series"]["travel"], dtype=float)
    v = np.asarray(run["series"][key], dtype=float)
    ok = np.isfinite(v)
    t, v = t[ok], v[ok]
    if not len(t):
        return np.full(len(grid), np.nan)
    idx = np.searchsorted(t, grid, side="right") - 1
    out = np.where(idx >= 0, v[np.clip(idx, 0, len(v) - 1)], np.nan)
    return out


def _bands(ax, runs: list[dict], key: str, scale: float, grid: np.ndarray) -> None:
    for mode in sorted({r["mode"] for r in runs}):
        rs = [r for r in runs if r["mode"] == mode]
        ys = np.array([_on_grid(r, key, grid) for r in rs]) * scale
        if not np.isfinite(ys).any():
            continue
        with np.errstate(all="ignore"):
            import warnings

            with warnings.catch_warnings():
                warnings.simplefilter("ignore", RuntimeWarning)
                med = np.nanmedian(ys, axis=0)
                lo, hi = np.nanpercentile(ys, 25, axis=0), np.nanpercentile(ys, 75, axis=0)
        c = COLORS.get(mode, "k")
        ax.plot(grid, med, color=c, label=f"{mode} (median of {len(rs)})")
        ax.fill_between(grid, lo, hi, color=c, alpha=0.2, lw=0)


def figure_transition_bands(obj: str, runs: list[dict], path: Path):
    """Fig. 4 / Fig. 9 transitions over seeds: Hausdorff and uncertainty against travel, median lines and
    interquartile bands per mode; the legend under the panels.

    Returns:
        the ``matplotlib.figure.Figure`` (already written to ``path``).
    """
    plt = _plt()
    fig, (ax_h, ax_u) = plt.subplots(1, 2, figsize=(11, 4.4))
    t_max = max(max(r["series"]["travel"]) for r in runs)
    grid = np.linspace(0.0, t_max, 300)
    _bands(ax_h, runs, "hausdorff", 100.0, grid)
    _bands(ax_u, runs, "uncertainty", 1.0, grid)
    ax_h.set(xlabel="travel since first contact [m]", ylabel="Hausdorff distance [cm]",
             title=f"object {obj}: Hausdorff distance (median, band: interquartile range over seeds)")
    ax_u.set(xlabel="travel since first contact [m]", ylabel="uncertainty, eq. (23) [V / prior variance]",
             title=f"object {obj}: uncertainty")
    for ax in (ax_h, ax_u):
        log_axis(ax)
        ax.title.set_fontsize(9)
    fig.tight_layout(rect=(0, 0.08, 1, 1))
    h, lab = ax_h.get_legend_handles_labels()
    legend_below(fig, h, lab, ncol=3)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return fig


def figure_similarity_bands(runs: list[dict], path: Path):
    """Fig. 5 / Fig. 10 over seeds, one column per object: the task correlation (top) and the paper's ratio
    (bottom) against travel, median and interquartile band, visual-tactile runs only.

    Returns:
        the ``matplotlib.figure.Figure`` (already written to ``path``).
    """
    import warnings

    plt = _plt()
    vt = [r for r in runs if r["mode"] == "visual-tactile"]
    objects = sorted({r["object"] for r in vt})
    cols = max(len(objects), 1)
    fig, axes = plt.subplots(2, cols, figsize=(3.2 * cols + 0.8, 6.0), squeeze=False, sharey="row")
    if vt:
        t_max = max(max(r["series"]["travel"]) for r in vt)
        grid = np.linspace(0.0, t_max, 300)
        for i, obj in enumerate(objects):
            rs = [r for r in vt if r["object"] == obj]
            for ax, key in ((axes[0, i], "correlation"), (axes[1, i], "similarity")):
                ys = np.array([_on_grid(r, key, grid) for r in rs])
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore", RuntimeWarning)
                    med = np.nanmedian(ys, axis=0)
                    lo, hi = np.nanpercentile(ys, 25, axis=0), np.nanpercentile(ys, 75, axis=0)
                ax.fill_between(grid, lo, hi, color=f"C{i}", alpha=0.25, lw=0, label="interquartile range")
                ax.plot(grid, med, color=f"C{i}", label="median")
                ax.tick_params(labelsize=7)
            axes[0, i].set(title=f"object {obj} ({len(rs)} seeds)", ylim=(-1.05, 1.05))
            axes[1, i].axhline(1.0, color="0.6", lw=0.6, ls="--")
            axes[1, i].set_xlabel("travel since first contact [m]", fontsize=8)
    axes[0, 0].set_ylabel("task correlation", fontsize=8)
    axes[1, 0].set_ylabel("paper's similarity $K_t[0,1]/K_t[0,0]$\n(a ratio: can exceed 1)", fontsize=8)
    fig.suptitle("similarity over seeds (visual-tactile): median and interquartile band", fontsize=10)
    fig.tight_layout(rect=(0, 0.06, 1, 1))
    h, lab = axes[0, 0].get_legend_handles_labels()
    legend_below(fig, h, lab, ncol=2)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return fig


#: What :func:`figure_paired` calls each metric it can draw (all distances [m], drawn in cm).
PAIRED_LABELS = {"final_hausdorff": "final Hausdorff distance", "final_chamfer": "final Chamfer distance"}


def figure_paired(rows: list[dict], path: Path, key: str = "final_hausdorff"):
    """A final distance per seed (``key``: the Hausdorff or the Chamfer distance, :data:`PAIRED_LABELS`),
    tactile-only and every other mode side by side, a line per seed; each panel has its own labelled log axis.

    Returns:
        the ``matplotlib.figure.Figure`` (already written to ``path``).
    """
    plt = _plt()
    objects = sorted({r["object"] for r in rows})
    modes = ["tactile"] + sorted({r["mode"] for r in rows} - {"tactile"})
    fig, axes = plt.subplots(1, len(objects), figsize=(3.2 * len(objects), 4), squeeze=False)
    for ax, obj in zip(axes[0], objects):
        by = {(r["mode"], r["seed"]): r[key] for r in rows if r["object"] == obj}
        seeds = sorted({s for _, s in by})
        for s in seeds:
            ys = [100 * by.get((m, s), np.nan) for m in modes]
            ax.plot(range(len(modes)), ys, "-o", color="0.6", ms=3, lw=0.7)
        for j, m in enumerate(modes):
            vals = [100 * by[(m, s)] for s in seeds if (m, s) in by and np.isfinite(by[(m, s)])]
            if vals:
                ax.plot([j - 0.2, j + 0.2], [np.median(vals)] * 2, color=COLORS.get(m, "k"), lw=3)
        ax.set_xticks(range(len(modes)), [m.replace("visual-tactile", "VT").replace("tactile", "T") for m in modes],
                      fontsize=7)
        ax.set(title=f"object {obj}", ylabel=f"{PAIRED_LABELS[key]} [cm]")
        log_axis(ax)
        ax.tick_params(labelsize=7)
    fig.suptitle(f"{PAIRED_LABELS[key]} per seed (grey: one seed across modes; bar: median)", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return fig
