"""The ``fit`` and ``replay`` commands' work on recorded data: fit a dataset (a user's files, a bag, a log's final
state) into a model, its figure, meshes and baselines; replay an exploration log step by step. The file formats they
read and write are :mod:`torch_gpioius.io`'s; this module fits and plots (it was ``torch_gpioius.io.offline``)."""

from __future__ import annotations

import csv
import json
import os
from pathlib import Path

import numpy as np
import torch
from tqdm.auto import tqdm

from .core.progress import status
from .io.checkpoints import save_checkpoint
from .io.outputs import FolderLock, StagedFiles, atomic_write
from .io.datasets import Dataset, DatasetError, load_dataset, read_records, replay
from .io.logs import load_logged_hyperparameters
from .models.gpiois import GPIOIS, INNER
from .geometry.metrics import hausdorff_distance, uncertainty_measure
from .models.estimator import EstimatorSettings
from .geometry.surfaces import (closed_curves, data_bounds, evaluate_grid, grid_resolution, zero_level_curves,
                                zero_level_mesh)
from .io.export import check_format

__all__ = ["fit_dataset", "fit_outputs", "replay_log", "data_bounds", "FIT_SCOUT", "fit_memory", "check_fit_memory",
           "available_memory", "why_no_estimate"]

#: Inner points above which a fit on a file scouts K_t's starts on a copy thinned to this many
#: (``GPIOIS.fit(scout=)``): below it every start runs on all the data, as a simulated run's first fit does.
FIT_SCOUT = 512


def _markers(ax, ds: Dataset, dim: int) -> None:
    """The observations on top of a figure, each kind with its own marker and a legend entry."""
    kinds = [((0, 0), dict(marker="o", color="k", s=6), "contacts (inner, y = 0)"),
             ((0, 1), dict(marker="o", facecolors="none", edgecolors="tab:orange", s=10), "inner free space (y = 1)"),
             ((1, 0), dict(marker="^", color="tab:cyan", s=8), "outer surface seen (y = 0)"),
             ((1, 1), dict(marker="x", color="0.5", s=8, linewidths=0.6), "outer free space (y = 1)")]
    for (task, y), style, label in kinds:
        m = (ds.task == task) & (ds.y == y)
        if m.any():
            ax.scatter(*ds.x[m, :dim].T, label=label, **style)


def has_surface(model, x: np.ndarray, resolution: float) -> bool:
    """Whether the inner estimate {mu_in = 0} has any surface in the data's box (:func:`data_bounds` of `(n, d)`
    points ``x``), on a grid of ``resolution`` [m]: a fit without one has no estimate to show or export."""
    bounds = data_bounds(x, pad=max(0.05, 2 * resolution))
    if x.shape[1] == 2:
        return bool(zero_level_curves(model, bounds, resolution, INNER))
    return zero_level_mesh(model, bounds, resolution, INNER) is not None


def _plot_estimate(model, ds: Dataset, path: Path, title: str, resolution: float) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from .geometry.metrics import prior_variance

    bounds = data_bounds(ds.x, pad=max(0.05, 2 * resolution))
    prior = prior_variance(model, INNER)
    if ds.x.shape[1] == 2:
        field = evaluate_grid(model, bounds, resolution, INNER)
        curves = zero_level_curves(model, bounds, resolution, INNER, field=field)
        fig, ax = plt.subplots(figsize=(7, 5.5))
        extent = [bounds[0, 0], bounds[1, 0], bounds[0, 1], bounds[1, 1]]
        im = ax.imshow(field.var.T / prior, origin="lower", extent=extent, cmap="Purples", vmin=0, vmax=1)
        fig.colorbar(im, ax=ax, label="$V_{in}$ / prior variance")
        for j, c in enumerate(curves):
            ax.plot(c[:, 0], c[:, 1], "-", color="tab:red", lw=2, label="estimate $\\mu_{in} = 0$" if j == 0 else None)
        _markers(ax, ds, 2)
        ax.set(xlabel="x [m]", ylabel="y [m]", title=title, aspect="equal")
    else:
        mesh = zero_level_mesh(model, bounds, resolution, INNER)
        fig = plt.figure(figsize=(7, 5.5))
        ax = fig.add_subplot(projection="3d")
        if mesh is not None:
            from matplotlib import colormaps
            from matplotlib.colors import LinearSegmentedColormap

            # Purples from a visible lilac up: its white end drew a certain estimate white on the white figure
            cmap = LinearSegmentedColormap.from_list("purples_visible", colormaps["Purples"](np.linspace(0.3, 1, 64)))
            _, var = model.predict(torch.tensor(np.asarray(mesh.triangles_center)), task=INNER)
            surf = ax.plot_trisurf(mesh.vertices[:, 0], mesh.vertices[:, 1], mesh.vertices[:, 2],
                                   triangles=mesh.faces, cmap=cmap, linewidth=0.1, edgecolor=(0.2, 0.1, 0.3, 0.25),
                                   vmin=0, vmax=1)
            surf.set_array(var.detach().numpy() / prior)
            # pad: the colour bar sat on the z axis' label
            fig.colorbar(surf, ax=ax, label="$V_{in}$ / prior variance on the estimate", shrink=0.6, pad=0.14)
        _markers(ax, ds, 3)
        ax.set(xlabel="x [m]", ylabel="y [m]", zlabel="z [m]")
        import textwrap

        ax.set_title(textwrap.fill(title, 55), fontsize=10)      # a long file name ran off the 3-D figure's edge
    ax.legend(fontsize=7, loc="best")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def fit_dataset(path: str | os.PathLike | Dataset, out: str | os.PathLike | None = None, *, settings=None,
                resolution: float | None = None, mesh: str | os.PathLike | None = None,
                outer_mesh: str | os.PathLike | None = None, force: bool = False, **deprecated) -> dict:
    """Learn K_t on a dataset (or the final state of a log); save a checkpoint, a figure and the estimate's meshes.

    Args:
        path: a ``.gpioius`` dataset or log, or a :class:`Dataset` (e.g. from
            :func:`torch_gpioius.io.importers.dataset_from_files`, which labels a user's files by estimator settings).
        out: folder for ``model.pt``, ``fit.png`` and ``fit.json`` (None: write nothing).
        resolution: grid spacing of the estimate [m] (its figure and meshes).
        settings: the estimator's settings (:class:`~torch_gpioius.models.estimator.EstimatorSettings` or a
            preset's name), or changes to the file's own (an
            :class:`~torch_gpioius.models.overrides.EstimatorOverrides`: kernel, sigma^2, what is learned; its
            labels are the file's); None: the file's own (a dataset records the settings it was labelled with), else
            the inverse multiquadric of 0.1 m and 0.006 of earlier files
            (:meth:`~torch_gpioius.models.estimator.EstimatorSettings.of_record`).
        mesh: write the inner estimate ``{mu_in = 0}`` here (PLY, OBJ, STL, OFF, GLB in 3-D; SVG, DXF, PLY, OBJ
            curves in 2-D; coloured by its variance where the format allows).
        outer_mesh: write the outer estimate here (visual-tactile data only).
        force: replace existing mesh files.
        **deprecated: ``kernel`` (an :class:`~torch_gpioius.kernels.ExactKernel` or a
            :class:`~torch_gpioius.kernels.KernelChoice`), ``noise`` (sigma^2) and ``learn`` ("task", "length" or
            "all": what the exact marginal likelihood learns), for one release: give
            ``settings=EstimatorOverrides(kernel=..., noise=..., learn=...)``.

    Returns:
        ``{"n", "settings", "task_covariance", "similarity", "correlation", "correlation_interval", "mll",
        "checkpoint", "figure", "estimate", "mesh", "outer_mesh"}``; ``estimate`` says whether the inner estimate
        has a surface in the data's box (on the figure's grid); ``correlation_interval`` is the 95 %
        profile-likelihood interval of the correlation (:meth:`torch_gpioius.GPIOIS.similarity_interval`). With
        ``out`` and 3-D data of both tasks, also ``"baselines"``: the simple baselines from the same observations
        (:mod:`torch_gpioius.baselines`), each surface written to ``out/baselines/<name>.ply``, with its gap.
    """
    from contextlib import ExitStack

    from .io.outputs import FileClaim, check_distinct, check_not_inputs
    from .models.overrides import loose_keywords

    loose = loose_keywords("fit_dataset", deprecated, ("kernel", "noise", "learn"))
    settings = _fit_settings(settings, loose["kernel"], loose["noise"], loose["learn"])
    check_distinct(mesh=mesh, outer_mesh=outer_mesh)
    inputs = list(path.meta.get("inputs") or []) if isinstance(path, Dataset) else [path]
    check_not_inputs(fit_outputs(out, mesh, outer_mesh), inputs)
    with ExitStack() as held:
        # the meshes claimed before the fit: an existing file, a folder that cannot be written or a second fit of
        # the same file is refused at once, not after the fit
        claims = {option: held.enter_context(FileClaim(target, force, option))
                  for option, target in (("--mesh", mesh), ("--outer-mesh", outer_mesh)) if target is not None}
        ds = path if isinstance(path, Dataset) else load_dataset(path)
        for claim in claims.values():
            check_format(claim.target, ds.x.shape[1])
        return _fit(ds, ds.meta.get("files", "dataset") if isinstance(path, Dataset) else path, out, resolution,
                    settings, claims.get("--mesh"), claims.get("--outer-mesh"))


#: What an exact fit of n observations holds at its peak, in float64 matrices of n x n (measured on users' files of
#: 1,467 to 2,870 observations: 14-21 of them) and the bytes the process holds besides (torch, the clouds).
FIT_MATRICES, FIT_BASE_BYTES = 24, 0.5e9


def fit_memory(n: int) -> float:
    """The bytes an exact fit of ``n`` observations is expected to need at its peak (K_t's Newton steps hold several
    `(n, n)` matrices): 1,000 contacts with their inside and free points, 2,870 observations, took 1.45 GB."""
    return FIT_BASE_BYTES + FIT_MATRICES * 8.0 * float(n) ** 2


def available_memory() -> float | None:
    """The bytes this machine can give a process now (Linux's MemAvailable), or None where it is not known."""
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return float(line.split()[1]) * 1024.0
    except OSError:
        pass
    return None


def check_fit_memory(ds: Dataset) -> None:
    """Refuse a fit that would run out of memory, before it starts (3,000 contacts took 7.5 GB and over five minutes
    before failing).

    Raises:
        MemoryError: naming the observations, the memory needed and available, and the remedy.
    """
    need, have = fit_memory(len(ds)), available_memory()
    if have is None or need <= 0.9 * have:
        return
    inner = int((ds.task == 0).sum())
    raise MemoryError(f"fit: {len(ds):,} observations ({inner:,} inner, {len(ds) - inner:,} outer) need about "
                      f"{need / 1e9:.1f} GB for the exact fit, more than the {have / 1e9:.1f} GB free on this machine; "
                      "thin the contacts (gpioius fit --contact-spacing 0.005, dataset_from_files(contact_spacing=)), "
                      "average the clouds in larger voxels (--voxel), or fit on a machine with more memory")


def why_no_estimate(ds: Dataset, length: float) -> str:
    """Why a fit's inner estimate has no surface in the data's box, as far as the data tell: too few contacts, or a
    kernel's length [m] far below the spacing of the inner observations (each then stands alone, the mean falls back
    to its prior of 1 between them); else that the zero level does not cross the box."""
    contacts = ds.x[ds.contact_rows()]
    if len(contacts) < 3:
        return f"only {len(contacts)} contact(s): too few to enclose a surface"
    inner = ds.x[ds.task == 0]
    from scipy.spatial import cKDTree

    spacing = float(np.median(cKDTree(inner).query(inner, k=2)[0][:, 1]))
    if length < 0.5 * spacing:
        return (f"the kernel's length ({length * 1000:.3g} mm) is far below the spacing of the inner observations "
                f"({spacing * 1000:.3g} mm, the median to the nearest): each stands alone and the mean returns to "
                "its prior between them; leave the length to the settings' rule (a fifth of the object) or give a "
                "longer one")
    return ("the inner zero level {mu_in = 0} does not cross the data's box: too few contacts around the object, or "
            "contacts that do not enclose it")


def fit_outputs(out, mesh, outer_mesh) -> dict:
    """``{option: path}`` of every file :func:`fit_dataset` writes (what
    :func:`~torch_gpioius.io.outputs.check_not_inputs` compares with the inputs)."""
    folder = {} if out is None else {f"--out ({n})": Path(out) / n for n in ("model.pt", "fit.png", "fit.json")}
    return {"--mesh": mesh, "--outer-mesh": outer_mesh, **folder}


def _fit_settings(settings, kernel, noise, learn):
    """``fit_dataset``'s settings: an :class:`EstimatorSettings` (a preset's name read), an
    :class:`~torch_gpioius.models.overrides.EstimatorOverrides` (changes to the file's own) or None; the deprecated
    ``kernel``, ``noise`` and ``learn`` folded in, with a DeprecationWarning.

    Raises:
        ValueError: a bad setting (names it).
    """
    from .models.overrides import EstimatorOverrides, warn_loose

    if not isinstance(settings, EstimatorOverrides) and settings is not None:
        settings = EstimatorSettings.of(settings)
    if not warn_loose("fit_dataset", 3, kernel=kernel, noise=noise, learn=learn):
        return settings
    changes = EstimatorOverrides(kernel=kernel, noise=noise, learn=learn)
    if settings is None:
        return changes
    return settings.merged(changes) if isinstance(settings, EstimatorOverrides) else changes.apply(settings)


def _carry(model, settings, ds: Dataset) -> None:
    """With ``labels.cover_carry`` and an outer mean standing for one gap, or a field of gaps, that the files' gap
    rules set (``dataset_from_files`` records ``cover_gap`` and that mean): the mean corrected once for the transfer
    the first fit learned (:func:`~torch_gpioius.exploration.observations.carried_mean`; a field raised by the same
    ``1 / r - 1``, :meth:`~torch_gpioius.models.gapfield.GapField.carried`), and K_t re-learned from there; an
    exploration does this step by step (its log's dataset carries no gap's mean to correct again)."""
    from .exploration.observations import carried_mean

    if (settings is None or not settings.labels.cover_carry or not isinstance(model, GPIOIS)
            or "cover_gap" not in ds.meta):
        return
    field = model.outer_field
    if field is not None and not field.carry:                # a gap per place: the same carry over the field
        model.set_outer_mean(field.carried(carried_mean(0.0, model.task_covariance)))
    elif field is None and model.outer_mean < 1.0:
        model.set_outer_mean(carried_mean(model.outer_mean, model.task_covariance))
    else:
        return
    model.fit(multi_start=False)


def _fit(ds: Dataset, path, out, resolution, settings, mesh, outer_mesh) -> dict:
    """:func:`fit_dataset` on a loaded dataset, its meshes claimed (:class:`~torch_gpioius.io.outputs.FileClaim`)."""
    from .exploration.config import LEARN_SIZE
    from .models.overrides import EstimatorOverrides
    from .io.export import write_estimate

    used = settings if settings is not None else _file_settings(ds)
    if isinstance(used, EstimatorOverrides):        # changes to the file's own (or its old header's kernel and noise)
        base = _file_settings(ds)
        used = used.apply(base if base is not None else EstimatorSettings.of_record(ds.meta))
    check_fit_memory(ds)
    status(f"fitting K_t on {len(ds):,} observations ({int((ds.task == 0).sum()):,} inner)")
    model = ds.to_model(settings=used)
    # a large file's first K_t: its starts scouted on a thinned copy, the full data re-learned from the basins found
    model = model.fit(scout=FIT_SCOUT) if isinstance(model, GPIOIS) else model.fit()
    _carry(model, used, ds)
    learn = used.learn if used is not None else "task"
    if learn != "task":
        model.learn_hyperparameters(*LEARN_SIZE, learn_noise=learn == "all")
    # 15 significant digits: a length passes through GPyTorch's positive constraint (softplus and back), which
    # leaves rounding in the last digit (0.10000000000000002) that a reader should not see
    info = {"n": len(ds), "n_inner": int((ds.task == 0).sum()), "n_outer": int((ds.task == 1).sum()),
            "kernel": model.kernel.describe(), "lengthscale": float(f"{model.lengthscale:.15g}"),
            "noise": float(f"{model.noise:.15g}"), "mll": float(model.log_marginal_likelihood()), "learn": learn,
            "settings": None if used is None else used.to_dict()}
    if ds.meta.get("camera_corrections") is not None:      # each capture's pose as corrected from the contacts
        info["camera_corrections"] = ds.meta["camera_corrections"]
    if model.hyper_result is not None:
        r = model.hyper_result
        info["learned"] = {"length": r.length, "noise": r.noise, "kept": r.kept, "mll_before": r.mll_full_before,
                           "evaluations": r.evaluations, "points": r.points}
    if isinstance(model, GPIOIS):
        status("the correlation's profile-likelihood interval")
        info["converged"] = bool(getattr(model.fit_result, "converged", True))
        if not info["converged"]:
            from .models.gpiois import fit_stop_reason

            info["fit_note"] = fit_stop_reason(model.fit_result)
        info["outer_mean"] = model.outer_mean           # 1 but where the settings' gap rules set it
        if model.outer_field is not None:
            f = model.outer_field
            info["outer_field"] = {"gaps": len(f.gaps), "median": f.prior, "length": f.length, "scale": f.scale,
                                   "noise": f.noise}
        info.update(task_covariance=model.task_covariance.tolist(), similarity=model.similarity,
                    correlation=model.correlation, correlation_interval=list(model.similarity_interval(0.95)),
                    similarity_support=model.similarity_support())
    res = grid_resolution(resolution, ds.x.shape[1], 0.005, 0.02)
    status("the estimate's surface")
    info["estimate"] = has_surface(model, ds.x, res)
    if not info["estimate"]:
        info["no_estimate"] = why_no_estimate(ds, model.lengthscale)
    info["mesh"] = info["outer_mesh"] = None
    # the meshes on export's grid (1 cm in 3-D): `fit --mesh` and `export --mesh` of the same data give one mesh
    mesh_res = grid_resolution(resolution, ds.x.shape[1])
    for key, target, task in (("mesh", mesh, INNER), ("outer_mesh", outer_mesh, 1)):
        if target is not None:
            if task == 1 and not isinstance(model, GPIOIS):
                raise ValueError("--outer-mesh: the data have no outer (camera) observations, so no outer estimate")
            info[key] = write_estimate(model, data_bounds(ds.x, pad=max(0.05, 2 * res)), target, mesh_res, task)
            info[key + "_resolution"] = mesh_res
    if out is not None:
        out = Path(out)
        out.mkdir(parents=True, exist_ok=True)
        # one fit's three files together: staged, then moved in when all are written (a failure, or a second fit
        # into the same folder, never leaves a model.pt of one fit beside the fit.json of another)
        with FolderLock(out, "gpioius fit"), StagedFiles(out) as staged:
            save_checkpoint(model, staged.path / "model.pt",
                            extra={"dataset": str(path), "settings": info["settings"]})
            _plot_estimate(model, ds, staged.path / "fit.png",
                           f"{' + '.join(Path(p).name for p in str(path).split(' + '))}: estimated inner shape "
                           "over its variance", res)
            info["checkpoint"], info["figure"] = str(out / "model.pt"), str(out / "fit.png")
            if isinstance(model, GPIOIS) and ds.x.shape[1] == 3:
                status("the simple baselines")
                info["baselines"] = _write_baselines(ds, model, staged.path / "baselines", out / "baselines",
                                                     mesh_res)
            atomic_write(staged.path / "fit.json", json.dumps(info, indent=2))
    return info


def _write_baselines(ds: Dataset, model, folder: Path, final: Path, resolution: float) -> dict:
    """The simple baselines (:mod:`torch_gpioius.baselines`) of a fit on files, from the same observations: each
    surface written to ``folder/<name>.ply`` (moved to ``final`` with the fit's other files), with the gap it was
    shrunk by. The camera's observations are the dataset's (a file's camera inside points already retracted where its
    contacts showed a wide cover); the contacts are taken in the order of their steps, then of the file."""
    from .baselines import BASELINE_EDGE, BASELINES, BaselineData

    folder.mkdir(parents=True, exist_ok=True)
    contact = ds.contact_rows()                      # each once: the first five are five touches
    order = np.argsort(ds.step[contact], kind="stable")
    data = BaselineData(ds.x[ds.task == 1], ds.y[ds.task == 1], ds.x[contact][order], model.kernel,
                        float(model.noise), data_bounds(ds.x, pad=max(0.05, 2 * resolution)), resolution,
                        BASELINE_EDGE)
    out = {}
    for name in BASELINES.names():
        estimate = BASELINES[name](data)
        if estimate is None:
            out[name] = {"mesh": None, "gap": None}
            continue
        atomic_write(folder / f"{name}.ply", estimate.surface.export(file_type="ply"))
        out[name] = {"mesh": str(final / f"{name}.ply"),
                     "gap": None if not np.isfinite(estimate.gap) else float(estimate.gap)}
    return out


def _file_settings(ds: Dataset):
    """The estimator settings a dataset records (``meta["estimator"]``), or None."""
    from .models.estimator import EstimatorSettings

    data = ds.meta.get("estimator")
    return EstimatorSettings.from_dict(data) if isinstance(data, dict) else None


def replay_log(path: str | os.PathLike, out: str | os.PathLike, *, every: int = 1, figures: int = 4,
               resolution: float = 0.01, progress: bool = True) -> list[dict]:
    """Re-run the estimation of an exploration log step by step and write per-step records and figures.

    For each logged step (every ``every``-th, and always the last) the observations up to that step are
    rebuilt (with the kernel length and noise the run had learned by then, where it learned them), K_t re-learned
    (warm-started), and the step's uncertainty (eq. 23), similarity and -- when the
    log names one of the built-in 2-D scenes -- the Hausdorff distance to its true inner shape (eq. 24) are
    recorded. Writes ``records.csv``, ``records.json`` and ``transition.png`` (the estimate at ``figures``
    evenly spaced steps; 2-D logs).
    """
    path, out = Path(path), Path(out)
    states, learned = {}, {}
    header = None
    for rec, ds in replay(path):      # one validated read: header fields, step numbers, observations
        header = ds.meta
        if rec.kind == "step":
            states[rec.meta["step"]] = ds
            if isinstance(rec.meta.get("hyperparameters"), dict):    # the length (and noise) the run had learned
                learned[rec.meta["step"]] = rec.meta["hyperparameters"]
    if header is None:
        header = next(iter(read_records(path))).meta
    steps = sorted(states)
    if not steps:
        # a dataset (an import, a saved run): replay by its step column, each state holding the observations that
        # had arrived by that step
        full = load_dataset(path)
        steps = sorted({int(k) for k in full.step[full.step > 0]})
        if not steps:
            raise DatasetError(f"{path}: every observation has step 0, nothing to replay step by step (use `fit`)")
        states = {k: Dataset(*(a[full.step <= k] for a in (full.x, full.y, full.task, full.step)), meta=full.meta)
                  for k in steps}
    chosen = steps[::max(1, every)]
    if chosen[-1] != steps[-1]:
        chosen.append(steps[-1])
    truth = None
    if header.get("dim") == 2:
        from .io.runs import known_truth

        shapes = known_truth(header)
        truth = None if shapes is None else shapes["inner"][0]
    out.mkdir(parents=True, exist_ok=True)
    # one writer at a time (a second replay into the folder is refused with the holder's pid), and its three files
    # moved in together when all are written
    with FolderLock(out, "gpioius replay"), StagedFiles(out) as staged:
        return _replay_steps(path, staged.path, states, learned, chosen, truth, figures, resolution, progress)


def _replay_steps(path: Path, out: Path, states: dict, learned: dict, chosen: list[int], truth, figures: int,
                  resolution: float, progress: bool) -> list[dict]:
    """:func:`replay_log`'s steps, records and figure, written into ``out`` (its staging folder)."""
    rows, snapshots = [], {}
    shots = set(np.unique(np.linspace(0, len(chosen) - 1, max(1, figures)).round().astype(int)).tolist())
    kt = None
    for i, k in enumerate(tqdm(chosen, desc=f"replay {path.name}", disable=not progress)):
        ds = states[k]
        model = load_logged_hyperparameters(ds.to_model(), learned.get(k), f"{path}: step {k}")
        if kt is not None and isinstance(model, GPIOIS):
            model.task_covariance = kt
            model.fit(multi_start=False)
        else:
            model.fit()
        kt = model.task_covariance if isinstance(model, GPIOIS) else None
        row = {"step": k, "n": len(ds), "similarity": model.similarity if kt is not None else float("nan"),
               "correlation": model.correlation if kt is not None else float("nan"),
               "uncertainty": float("nan"), "hausdorff": float("nan")}
        bounds = data_bounds(ds.x)
        if ds.x.shape[1] == 2:
            curves = zero_level_curves(model, bounds, resolution, INNER)
            if curves:
                row["uncertainty"] = uncertainty_measure(model, curves, INNER)
                if truth is not None and closed_curves(curves):
                    row["hausdorff"] = hausdorff_distance(curves, [truth], spacing=2e-3)
            if i in shots:
                snapshots[k] = (curves, ds.x[ds.contact_rows()])
        else:
            mesh = zero_level_mesh(model, bounds, max(resolution, 0.02), INNER)
            if mesh is not None:
                row["uncertainty"] = uncertainty_measure(model, mesh, INNER)
        rows.append(row)
    with open(out / "records.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    (out / "records.json").write_text(json.dumps(rows, indent=1))
    why = {"hausdorff": "no known true shape (not a built-in 2-D scene)",
           "uncertainty": "no estimated surface in the box of the observations",
           "correlation": "tactile-only data (no outer observations)",
           "similarity": "tactile-only data (no outer observations)"}
    _plot_replay(rows, snapshots, truth, out / "transition.png", path.name, why)
    return rows


def _plot_replay(rows: list[dict], snapshots: dict, truth, path: Path, name: str, why: dict[str, str]) -> None:
    """The replay's transitions (uncertainty, Hausdorff, correlation and the paper's similarity over the steps) and,
    for 2-D logs, the estimate at a few steps."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ncols = max(4, len(snapshots))
    fig, axes = plt.subplots(2 if snapshots else 1, ncols, figsize=(3.4 * ncols, 6.6 if snapshots else 3.4),
                             squeeze=False)
    steps = [r["step"] for r in rows]
    panels = (("uncertainty", "uncertainty, eq. (23)\n[V / prior variance]"),
              ("hausdorff", "Hausdorff distance [cm]"),
              ("correlation", "task correlation\n$K_t[0,1]/\\sqrt{K_t[0,0]K_t[1,1]}$"),
              ("similarity", "paper's similarity K_t[0,1]/K_t[0,0]\n(a ratio: can exceed 1)"))
    for ax, (key, label) in zip(axes[0], panels):
        v = np.array([r[key] for r in rows], dtype=float) * (100 if key == "hausdorff" else 1)
        if np.isfinite(v).any():
            ax.plot(steps, v, ".-")
        else:
            ax.text(0.5, 0.5, "not available:\n" + why[key].replace(" (", "\n("), ha="center", va="center",
                    transform=ax.transAxes, color="0.4", fontsize=8)
        ax.set(xlabel="step", ylabel=label)
    for ax in axes[0][len(panels):]:
        ax.axis("off")
    if snapshots:
        for ax, (k, (curves, touched)) in zip(axes[1], snapshots.items()):
            if truth is not None:
                ax.plot(*np.vstack([truth, truth[:1]]).T, "k--", lw=1, label="true inner shape")
            for j, c in enumerate(curves):
                ax.plot(c[:, 0], c[:, 1], "r-", label="estimate $\\mu_{in} = 0$" if j == 0 else None)
            ax.plot(touched[:, 0], touched[:, 1], "b.", ms=2, label="contacts")
            ax.set(title=f"step {k}", aspect="equal", xlabel="x [m]", ylabel="y [m]")
            ax.tick_params(labelsize=6)
        axes[1][0].legend(fontsize=6)
        for ax in axes[1][len(snapshots):]:
            ax.axis("off")
    fig.suptitle(f"replay of {name}", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
