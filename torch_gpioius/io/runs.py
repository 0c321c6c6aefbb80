"""A run as a sequence of steps, for viewers and exports: observations, path, learned parameters and the model at
each step of an exploration log, or of a dataset by its step column, and the true shapes when the run names a
built-in world."""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import trimesh
import torch

from .datasets import Dataset, DatasetError, load_dataset, replay
from .logs import load_logged_hyperparameters, logged_gap_field, step_values

__all__ = ["RunHistory", "load_run", "known_truth", "estimate_surface"]


@dataclass
class RunHistory:
    """Every step of one run.

    Attributes:
        path: the file read.
        meta: its header (world, scene, mode, theta, noise, ...).
        steps: `(K,)` step numbers, increasing (0 = before exploring, when the file has it).
        states: the observations after each step (:class:`Dataset`), keyed by step.
        params: per step, what the run had learned: ``kt`` `(2, 2)` (visual-tactile), ``local_params`` (local
            model), ``similarity`` / ``correlation`` / ``hausdorff`` / ``estimate`` (1: a surface to judge, 0: none) as
            recorded (NaN when not).
        trajectory: `(m, d)` fingertip positions in time order [m]; ``trajectory_step`` `(m,)` the step each
            belongs to.

    A step of a tactile-patch run also has ``pad_pose`` `(4, 4)` (pad to base) and ``pad_size`` `(2,)` [m] in its
    ``params``: where the gel pad was when it was read.
    """

    path: Path
    meta: dict
    steps: list[int]
    states: dict[int, Dataset]
    params: dict[int, dict] = field(default_factory=dict)
    trajectory: np.ndarray | None = None
    trajectory_step: np.ndarray | None = None

    @property
    def dim(self) -> int:
        return int(self.meta["dim"])

    @property
    def name(self) -> str:
        return self.path.stem

    def nearest_step(self, step: int) -> int:
        """The last recorded step at or before ``step`` (the first one if ``step`` precedes them all)."""
        i = int(np.searchsorted(self.steps, step, side="right")) - 1
        return self.steps[max(i, 0)]

    def model_at(self, step: int):
        """The model of the run after ``step``: rebuilt from the observations with the logged K_t / local
        parameters (no re-learning), or fitted where the file records none (datasets)."""
        k = self.nearest_step(step)
        ds, p = self.states[k], self.params.get(k, {})
        settings = self.settings()
        has_outer = bool((ds.task == 1).any())
        if not has_outer or self.meta.get("mode") == "tactile":
            model = settings.make_model(ds.x[ds.task == 0], ds.y[ds.task == 0])
            return load_logged_hyperparameters(model, p.get("hyperparameters"), f"{self.path}: step {k}")
        if "local_params" in p and self.meta.get("regions"):
            model = settings.make_model(ds.x, ds.y, ds.task, regions=int(self.meta["regions"]))
            return model.set_params(p["local_params"])
        if "kt" in p and np.isfinite(p["kt"]).all():
            model = settings.make_model(ds.x, ds.y, ds.task, task_covariance=torch.as_tensor(p["kt"]))
            model.set_outer_mean(p.get("outer_field") or p.get("outer_mean", 1.0))
            return load_logged_hyperparameters(model, p.get("hyperparameters"), f"{self.path}: step {k}")
        return settings.make_model(ds.x, ds.y, ds.task).fit()

    def settings(self):
        """The estimator's settings the run recorded (its header's ``estimator``; for files written before, its
        kernel and noise: :meth:`~torch_gpioius.models.estimator.EstimatorSettings.of_record`).

        Raises:
            DatasetError: settings the header holds that cannot be read (names the file).
        """
        from ..models.estimator import EstimatorSettings

        try:
            return EstimatorSettings.of_record(self.meta)
        except ValueError as exc:
            raise DatasetError(f"{self.path}: {exc}") from None

    def kernel(self):
        """A new copy of the run's kernel as its recorded settings describe it (the inverse multiquadric of the
        header's ``theta`` in files that describe none)."""
        return self.settings().new_kernel()

    def pad_footprints(self, step: int) -> np.ndarray:
        """`(p, 4, 3)` the corners of the gel pad at every patch up to ``step`` [m], base frame (in order around
        the pad; none for point-touch runs)."""
        corners = []
        for k in self.steps:
            if k > step:
                break
            p = self.params.get(k, {})
            if "pad_pose" in p and "pad_size" in p:
                w, h = 0.5 * np.asarray(p["pad_size"], dtype=np.float64)
                local = np.array([[-w, -h, 0.0], [w, -h, 0.0], [w, h, 0.0], [-w, h, 0.0]])
                pose = np.asarray(p["pad_pose"], dtype=np.float64)
                corners.append(local @ pose[:3, :3].T + pose[:3, 3])
        return np.asarray(corners, dtype=np.float64).reshape(-1, 4, 3)

    def series(self, key: str) -> np.ndarray:
        """`(K,)` a recorded per-step value (``similarity``, ``correlation``, ``hausdorff``) over :attr:`steps`."""
        return np.array([self.params.get(k, {}).get(key, math.nan) for k in self.steps], dtype=np.float64)


def load_run(path: str | os.PathLike) -> RunHistory:
    """Read a log or a dataset (see :class:`RunHistory`).

    A log gives one state per step record (and the state before exploring); a dataset gives one state per value
    of its step column (observations with ``step <= k``).

    Raises:
        DatasetError: unreadable or invalid files (names the file and the field), or a file with no observation.
    """
    path = Path(path)
    states: dict[int, Dataset] = {}
    params: dict[int, dict] = {}
    traj, traj_step = [], []
    header = None
    for rec, ds in replay(path):
        header = ds.meta
        if rec.kind == "step":
            k = int(rec.meta["step"])
            states[k] = ds
            a = rec.arrays
            v = step_values(rec.meta, f"{path}: step record ending at byte {rec.end}")
            p = {"similarity": v["similarity"], "correlation": v["correlation"], "hausdorff": v["hausdorff"],
                 "estimate": v["estimate"],
                 "contact_distance": v.get("contact_distance", math.nan),
                 "contact_on_body": v.get("contact_on_body", math.nan),
                 "length": v["length"], "noise": v["noise"]}
            if isinstance(rec.meta.get("hyperparameters"), dict):   # a run that learned the length (and noise)
                p["hyperparameters"] = rec.meta["hyperparameters"]
            if isinstance(rec.meta.get("outer_mean"), (int, float)):  # logged since 2026-11-27
                p["outer_mean"] = float(rec.meta["outer_mean"])
            if isinstance(rec.meta.get("outer_field"), dict):        # logged since 2026-11-29
                p["outer_field"] = logged_gap_field(rec.meta, rec.arrays, f"{path}: step record ending at byte "
                                                                          f"{rec.end}")
            if isinstance(rec.meta.get("camera_corrections"), dict):  # the step that corrected the captures
                p["camera_corrections"] = rec.meta["camera_corrections"]
            for key in ("kt", "local_params", "contact", "pad_pose", "pad_size"):
                if key in a:
                    p[key] = np.asarray(a[key], dtype=np.float64)
            params[k] = p
        elif rec.kind == "observations" and not states:
            states[0] = ds
        # the fingertip's path in time order: each step's, then its evidence actions' (logged since 2026-11)
        if rec.kind in ("step", "tap", "recovery") and len(rec.arrays.get("path", ())):
            traj.append(np.asarray(rec.arrays["path"], dtype=np.float64))
            traj_step.append(np.full(len(rec.arrays["path"]), int(rec.meta["step"])))
    if header is None:
        raise DatasetError(f"{path}: no observations")
    if not any(k > 0 for k in states):   # a dataset: states by its step column
        full = load_dataset(path)
        ks = sorted({0, *(int(k) for k in full.step)})
        states = {k: Dataset(*(a[full.step <= k] for a in (full.x, full.y, full.task, full.step)), meta=full.meta,
                             trace=full.trace) for k in ks if (full.step <= k).any()}
        if "positions" in full.trace and len(full.trace["positions"]):
            traj = [full.trace["positions"]]
            traj_step = [np.zeros(len(full.trace["positions"]), np.int64)]
    if not states:
        raise DatasetError(f"{path}: the file holds no observations")
    trajectory = np.concatenate(traj) if traj else None
    return RunHistory(path, dict(header), sorted(states), states, params, trajectory,
                      np.concatenate(traj_step) if traj_step else None)


def known_truth(meta: dict) -> dict | None:
    """The true shapes of a registered world's built-in object named by a header (``world`` and ``scene``), or None.

    Returns:
        ``World.truth()`` of that object: 2-D ``{"inner": [(m, 2)], "outer": [(m, 2)]}`` closed polylines [m]; 3-D
        ``{"inner": Trimesh, "outer": Trimesh | None}`` (MuJoCo covers settle at run time: their outer shape is what
        the camera saw). None when the run's world or object is not a built-in one (a real robot, a user's scene) or
        its optional dependency is missing.
    """
    from ..exploration.registry import world_entry

    if meta.get("scene_file"):          # a user's scene: its file, while it is the one the run explored
        from ..sim.scenefile import truth_of_scene_file

        return truth_of_scene_file(meta)
    world, name = meta.get("world"), meta.get("scene")
    if not isinstance(world, str) or not isinstance(name, str):
        return None
    try:
        entry = world_entry(world)
        if name not in entry.object_names:
            return None
        return entry.build(name).truth()
    except (ValueError, ImportError):
        return None


def estimate_surface(model, bounds: np.ndarray, resolution: float, task: int = 0):
    """The estimated surface ``{mu = 0}`` of ``task`` and its posterior variance, its vertices on the level set (the
    converged ruler's meshes and curves, :func:`~torch_gpioius.geometry.surfaces.converged_level_mesh`, without a
    further split: a mesh of ``resolution`` whose every vertex lies on the estimate, not interpolated on the grid's
    edges).

    Returns:
        2-D: ``(curves, variances)`` lists of `(m, 2)` polylines [m] and `(m,)` variances at their vertices;
        3-D: ``(mesh, variance)``, a :class:`trimesh.Trimesh` and `(V,)` variances at its vertices; ``(None, None)``
        (3-D) or ``([], [])`` (2-D) when the level set does not cross the box.
    """
    from ..geometry.surfaces import converged_level_curves, converged_level_mesh

    if bounds.shape[1] == 2:
        curves = converged_level_curves(model, bounds, resolution, task, edge=resolution)
        var = []
        for c in curves:
            var.append(_variance(model, np.asarray(c), task))
        return curves, var
    mesh = converged_level_mesh(model, bounds, resolution, task, edge=resolution)
    if mesh is None:
        return None, None
    mesh = trimesh.Trimesh(vertices=mesh.vertices, faces=mesh.faces, process=False)     # without the ruler's notes
    return mesh, _variance(model, np.asarray(mesh.vertices), task)


def _variance(model, x: np.ndarray, task: int) -> np.ndarray:
    with torch.no_grad():
        if getattr(model, "num_tasks", 1) > 1:
            return model.predict(torch.tensor(x), task=task)[1].numpy()
        return model.predict(torch.tensor(x))[1].numpy()
