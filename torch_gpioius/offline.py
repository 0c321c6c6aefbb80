"""Offline work on logged data: fit a dataset, replay an exploration log step by step."""

from __future__ import annotations

import csv
import json
import os
from pathlib import Path

import numpy as np
import torch
from tqdm.auto import tqdm

from .checkpoints import save_checkpoint
from .datasets import Dataset, DatasetError, load_dataset, read_records, replay
from .gpiois import GPIOIS, INNER
from .metrics import hausdorff_distance, uncertainty_measure
from .surfaces import closed_curves, evaluate_grid, zero_level_curves, zero_level_mesh

__all__ = ["fit_dataset", "replay_log", "data_bounds"]


def data_bounds(x: np.ndarray, pad: float = 0.05) -> np.ndarray:
    """`(d, 2)` axis-aligned bounds of `(n, d)` points, padded by ``pad`` [m]."""
    return np.stack([x.min(0) - pad, x.max(0) + pad], axis=-1)


def _plot_estimate(model, ds: Dataset, path: Path, title: str, resolution: float) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    bounds = data_bounds(ds.x, pad=max(0.05, 2 * resolution))
    if ds.x.shape[1] == 2:
        field = evaluate_grid(model, bounds, resolution, INNER)
        curves = zero_level_curves(model, bounds, resolution, INNER, field=field)
        fig, ax = plt.subplots(figsize=(6, 5))
        im = ax.imshow(field.var.T, origin="lower", extent=bounds.reshape(-1), cmap="viridis")
        fig.colorbar(im, ax=ax, label="posterior variance of F_in")
        for c in curves:
            ax.plot(c[:, 0], c[:, 1], "r-", lw=2)
        for task, marker in ((0, "k."), (1, "w.")):
            for y, alpha in ((0, 1.0), (1, 0.35)):
                m = (ds.task == task) & (ds.y == y)
                if m.any():
                    ax.plot(ds.x[m, 0], ds.x[m, 1], marker, ms=3, alpha=alpha)
        ax.set(xlabel="x [m]", ylabel="y [m]", title=title, aspect="equal")
    else:
        mesh = zero_level_mesh(model, bounds, resolution, INNER)
        fig = plt.figure(figsize=(6, 5))
        ax = fig.add_subplot(projection="3d")
        if mesh is not None:
            _, var = model.predict(torch.as_tensor(mesh.triangles_center), task=INNER)
            surf = ax.plot_trisurf(mesh.vertices[:, 0], mesh.vertices[:, 1], mesh.vertices[:, 2],
                                   triangles=mesh.faces, cmap="viridis", linewidth=0)
            surf.set_array(var.detach().numpy())
            fig.colorbar(surf, ax=ax, label="posterior variance of F_in", shrink=0.6)
        inner = ds.task == 0
        ax.scatter(*ds.x[inner & (ds.y == 0)].T, c="k", s=4)
        ax.set(xlabel="x [m]", ylabel="y [m]", zlabel="z [m]", title=title)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def fit_dataset(path: str | os.PathLike, out: str | os.PathLike | None = None, *, theta: float | None = None,
                noise: float | None = None, resolution: float | None = None) -> dict:
    """Learn K_t on a dataset (or the final state of a log); save a checkpoint and a figure.

    Returns:
        ``{"n", "task_covariance", "similarity", "correlation", "mll", "checkpoint", "figure"}``.
    """
    ds = load_dataset(path)
    model = ds.to_model(theta=theta, noise=noise).fit()
    info = {"n": len(ds), "n_inner": int((ds.task == 0).sum()), "n_outer": int((ds.task == 1).sum()),
            "theta": float(model.theta), "noise": float(model.noise),
            "mll": float(model.log_marginal_likelihood())}
    if isinstance(model, GPIOIS):
        info.update(task_covariance=model.task_covariance.tolist(), similarity=model.similarity,
                    correlation=model.correlation)
    if out is not None:
        out = Path(out)
        out.mkdir(parents=True, exist_ok=True)
        info["checkpoint"] = str(save_checkpoint(model, out / "model.pt", extra={"dataset": str(path)}))
        res = resolution or (0.005 if ds.x.shape[1] == 2 else 0.02)
        fig = out / "fit.png"
        _plot_estimate(model, ds, fig, f"{Path(path).name}: mu_in = 0 over the variance", res)
        info["figure"] = str(fig)
        (out / "fit.json").write_text(json.dumps(info, indent=2))
    return info


def replay_log(path: str | os.PathLike, out: str | os.PathLike, *, every: int = 1, figures: int = 4,
               resolution: float = 0.01, progress: bool = True) -> list[dict]:
    """Re-run the estimation of an exploration log step by step and write per-step records and figures.

    For each logged step (every ``every``-th, and always the last) the observations up to that step are
    rebuilt, K_t re-learned (warm-started), and the step's uncertainty (eq. 23), similarity and -- when the
    log names one of the built-in 2-D scenes -- the Hausdorff distance to its true inner shape (eq. 24) are
    recorded. Writes ``records.csv``, ``records.json`` and ``transition.png`` (the estimate at ``figures``
    evenly spaced steps; 2-D logs).
    """
    path, out = Path(path), Path(out)
    states = {}
    header = None
    for rec, ds in replay(path):      # one validated read: header fields, step numbers, observations
        header = ds.meta
        if rec.kind == "step":
            states[rec.meta["step"]] = ds
    if header is None:
        header = next(iter(read_records(path))).meta
    steps = sorted(states)
    if not steps:
        raise DatasetError(f"{path}: no step records: this is a dataset, not an exploration log (use `fit`)")
    chosen = steps[::max(1, every)]
    if chosen[-1] != steps[-1]:
        chosen.append(steps[-1])
    truth = None
    if header.get("dim") == 2 and header.get("scene"):
        from .sim import paper_objects_2d

        scene = paper_objects_2d().get(header["scene"])
        truth = None if scene is None else scene.inner_boundary
    out.mkdir(parents=True, exist_ok=True)
    rows, snapshots = [], {}
    shots = set(np.unique(np.linspace(0, len(chosen) - 1, max(1, figures)).round().astype(int)).tolist())
    kt = None
    for i, k in enumerate(tqdm(chosen, desc=f"replay {path.name}", disable=not progress)):
        ds = states[k]
        model = ds.to_model()
        if kt is not None and isinstance(model, GPIOIS):
            model.task_covariance = kt
            model.fit(multi_start=False)
        else:
            model.fit()
        kt = model.task_covariance if isinstance(model, GPIOIS) else None
        row = {"step": k, "n": len(ds), "similarity": model.similarity if kt is not None else float("nan"),
               "uncertainty": float("nan"), "hausdorff": float("nan")}
        if ds.x.shape[1] == 2:
            bounds = data_bounds(ds.x)
            curves = zero_level_curves(model, bounds, resolution, INNER)
            if curves:
                row["uncertainty"] = uncertainty_measure(model, curves, INNER)
                if truth is not None and closed_curves(curves):
                    row["hausdorff"] = hausdorff_distance(curves, [truth], spacing=2e-3)
            if i in shots:
                snapshots[k] = (curves, ds.x[(ds.task == 0) & (ds.y == 0)])
        rows.append(row)
    with open(out / "records.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    (out / "records.json").write_text(json.dumps(rows, indent=1))
    if snapshots:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, axes = plt.subplots(1, len(snapshots), figsize=(3.2 * len(snapshots), 3.4), squeeze=False)
        for ax, (k, (curves, touched)) in zip(axes[0], snapshots.items()):
            if truth is not None:
                ax.plot(*np.vstack([truth, truth[:1]]).T, "k--", lw=1)
            for c in curves:
                ax.plot(c[:, 0], c[:, 1], "r-")
            ax.plot(touched[:, 0], touched[:, 1], "b.", ms=2)
            ax.set(title=f"step {k}", aspect="equal")
            ax.tick_params(labelsize=6)
        fig.tight_layout()
        fig.savefig(out / "transition.png", dpi=110)
        plt.close(fig)
    return rows
