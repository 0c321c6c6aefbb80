"""Figures of a sweep over seeds: transitions as median lines with bands, the similarity as bands, and the paired
final Hausdorff distances per seed."""

from __future__ import annotations

from pathlib import Path

import numpy as np

__all__ = ["figure_transition_bands", "figure_similarity_bands", "figure_paired"]

COLORS = {"visual-tactile": "tab:red", "tactile": "tab:blue", "visual-tactile+taps": "tab:purple",
          "local": "tab:orange", "local+taps": "tab:brown"}


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


def figure_transition_bands(obj: str, runs: list[dict], path: Path) -> None:
    """Fig. 4 / Fig. 9 transitions over seeds: Hausdorff and uncertainty against travel, median lines and
    interquartile bands per mode."""
    plt = _plt()
    fig, (ax_h, ax_u) = plt.subplots(1, 2, figsize=(11, 4))
    t_max = max(max(r["series"]["travel"]) for r in runs)
    grid = np.linspace(0.0, t_max, 300)
    _bands(ax_h, runs, "hausdorff", 100.0, grid)
    _bands(ax_u, runs, "uncertainty", 1.0, grid)
    ax_h.set(xlabel="travel since first contact [m]", ylabel="Hausdorff distance [cm]", yscale="log",
             title=f"object {obj}: Hausdorff distance (median, band: interquartile range over seeds)")
    ax_u.set(xlabel="travel since first contact [m]", ylabel="uncertainty, eq. (23) [V / prior variance]",
             yscale="log", title=f"object {obj}: uncertainty")
    for ax in (ax_h, ax_u):
        ax.legend(fontsize=7)
        ax.title.set_fontsize(9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def figure_similarity_bands(runs: list[dict], path: Path) -> None:
    """Fig. 5 / Fig. 10 over seeds: the task correlation (left) and the paper's ratio (right) against travel,
    median and interquartile band per object, visual-tactile runs only."""
    plt = _plt()
    fig, (ax_c, ax_s) = plt.subplots(1, 2, figsize=(11, 4))
    vt = [r for r in runs if r["mode"] == "visual-tactile"]
    if vt:
        t_max = max(max(r["series"]["travel"]) for r in vt)
        grid = np.linspace(0.0, t_max, 300)
        for i, obj in enumerate(sorted({r["object"] for r in vt})):
            rs = [r for r in vt if r["object"] == obj]
            for ax, key in ((ax_c, "correlation"), (ax_s, "similarity")):
                ys = np.array([_on_grid(r, key, grid) for r in rs])
                import warnings

                with warnings.catch_warnings():
                    warnings.simplefilter("ignore", RuntimeWarning)
                    med = np.nanmedian(ys, axis=0)
                    lo, hi = np.nanpercentile(ys, 25, axis=0), np.nanpercentile(ys, 75, axis=0)
                ax.plot(grid, med, color=f"C{i}", label=f"object {obj} ({len(rs)} seeds)")
                ax.fill_between(grid, lo, hi, color=f"C{i}", alpha=0.2, lw=0)
    ax_c.set(xlabel="travel since first contact [m]", ylabel="task correlation", ylim=(-1.05, 1.05),
             title="task correlation (median, band: interquartile range over seeds)")
    ax_s.axhline(1.0, color="0.6", lw=0.6, ls="--")
    ax_s.set(xlabel="travel since first contact [m]", ylabel="paper's similarity $K_t[0,1]/K_t[0,0]$",
             title="the paper's similarity (a ratio of amplitudes: can exceed 1)")
    for ax in (ax_c, ax_s):
        ax.legend(fontsize=7)
        ax.title.set_fontsize(9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def figure_paired(rows: list[dict], path: Path, key: str = "final_hausdorff_m") -> None:
    """Final Hausdorff distance per seed, tactile-only and every other mode side by side, a line per seed."""
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
        ax.set(title=f"object {obj}", ylabel="final Hausdorff distance [cm]" if obj == objects[0] else None)
        ax.set_yscale("log")
    fig.suptitle("final Hausdorff distance per seed (grey: one seed across modes; bar: median)", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
