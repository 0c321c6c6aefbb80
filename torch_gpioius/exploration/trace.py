"""The record of one exploration: per-step values (the vocabulary of
:data:`~torch_gpioius.exploration.state.RECORD_FIELDS`), the path, the contacts and the final model."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..geometry.metrics import SHAPE_METRICS

__all__ = ["Trace"]


@dataclass
class Trace:
    """Per-step records of one exploration (record 0 is the state right after the first contact).

    Attributes:
        mode: "visual-tactile" or "tactile".
        scene_name: the world's name.
        hausdorff: `(n,)` Hausdorff distance [m] between the whole estimated zero set {mu_in = 0} and the true inner
            surface (eq. 24, the paper's); NaN where not measured or without a closed estimate.
        uncertainty: `(n,)` uncertainty measure (eq. 23) over the estimated inner surface; NaN without one.
        similarity: `(n,)` the paper's similarity K_t[0,1] / K_t[0,0] (NaN in tactile mode).
        travel: `(n,)` fingertip travel since the first contact [m].
        path: `(k, d)` every position the fingertip occupied, approach included [m].
        contacts: `(n, d)` contact positions [m].
        model: the final fitted model (``GPIOIS``, ``GPIS`` or ``LocalGPIOIS``).
        step_time: `(n,)` wall time of each planning step (plan + ingest + re-learn; robot motion excluded) [s].
        terminated: why it stopped: "once-around", "travel", "max_steps", "lost-contact" or "refused: ...".
        task_covariance: `(n, 2, 2)` learned K_t per record (NaN in tactile mode).
        retracted: free-space samples removed because a later contact landed within the margin.
        robot_time: `(n,)` robot clock at each record [s].
        final_mesh: 3-D only: the last estimated inner surface within the exploration range (``trimesh``).
        hausdorff_touched: `(n,)` Hausdorff distance [m] between the *touched* pieces of {mu_in = 0} (those the
            fingertip slid along, :func:`torch_gpioius.geometry.surfaces.touched_pieces`) and the true inner surface.
        correlation: `(n,)` task correlation K_t[0,1] / sqrt(K_t[0,0] K_t[1,1]) (NaN in tactile mode).
        correlation_interval: `(n, 2)` profile-likelihood interval of the correlation (NaN where not computed).
        taps: `(n,)` cumulative number of evidence actions (taps).
        world: the world's registry name ("planar", "forcefield", "mujoco", "robot", or a user's).
        evidence: the evidence policy's name ("taps") or None.
        region_correlation: `(n, R)` task correlation of each region (``regions=R``; `(n, 0)` otherwise).
        touch: the touch model's name ("point", "patch").
        contact_distance: `(n,)` distance of each step's contact from the true inner surface [m] (NaN unknown).
        contact_on_body: `(n,)` 1 where the fingertip touched the body itself, 0 where only the cover (NaN unknown).
        recoveries: `(n,)` cumulative number of recoveries from a stall.
        reapproaches: `(n,)` cumulative number of re-approaches after lost contact.
        reapproach_travel: `(n,)` cumulative travel of those re-approaches [m] (part of ``travel``).
        shape: the field's shape metrics per record, ``{name: (n,)}`` for each of
            :data:`torch_gpioius.geometry.metrics.SHAPE_METRICS` (Chamfer, F-scores, bias, observed Hausdorff,
            unseen share; NaN where not measured or where the world knows no truth).
        estimate: `(n,)` 1 where the estimate was measured and has a surface to judge, 0 where it has none (no
            estimate), NaN where not measured.
        truncation: `(n,)` bound on the truncated outer basis' change of the Gram matrix relative to sigma^2
            (``outer_tol``; 0 with the exact engines).
        fit_gap: `(n,)` MLL gain predicted to remain from each record's K_t to the optimum [nats] (0 after a full
            re-learning; a held or tracked K_t's, ``PatchTouch.track``).
        length: `(n,)` the kernel's length in use [m] (NaN for a kernel without one; changes where learned).
        noise: `(n,)` sigma^2 in use.
        time_split: where the run's wall time went [s]: ``{"method", "camera", "contact", "measuring", "total"}``
            (:class:`torch_gpioius.exploration.timing.PartClock`; a resumed run's: since it resumed).
        vision_plain: ``(x, y)`` the first capture labelled without the ray smoothing (each point in the voxel it was
            measured in), where the settings smooth; None otherwise or on resume (the simple baselines' second input).
        camera_corrections: what each camera view was moved by when the contacts corrected the captures
            (``ObservationPolicy.camera_bound``), or None.
    """

    mode: str
    scene_name: str
    hausdorff: np.ndarray
    uncertainty: np.ndarray
    similarity: np.ndarray
    travel: np.ndarray
    path: np.ndarray
    contacts: np.ndarray
    model: object
    step_time: np.ndarray
    terminated: str
    task_covariance: np.ndarray = field(default_factory=lambda: np.zeros((0, 2, 2)))
    retracted: int = 0
    robot_time: np.ndarray = field(default_factory=lambda: np.zeros(0))
    final_mesh: object = None
    hausdorff_touched: np.ndarray = field(default_factory=lambda: np.zeros(0))
    correlation: np.ndarray = field(default_factory=lambda: np.zeros(0))
    correlation_interval: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    taps: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    world: str = ""
    evidence: str | None = None
    region_correlation: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    touch: str = "point"
    contact_distance: np.ndarray = field(default_factory=lambda: np.zeros(0))
    contact_on_body: np.ndarray = field(default_factory=lambda: np.zeros(0))
    recoveries: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    truncation: np.ndarray = field(default_factory=lambda: np.zeros(0))
    fit_gap: np.ndarray = field(default_factory=lambda: np.zeros(0))
    length: np.ndarray = field(default_factory=lambda: np.zeros(0))
    noise: np.ndarray = field(default_factory=lambda: np.zeros(0))
    estimate: np.ndarray = field(default_factory=lambda: np.zeros(0))
    reapproaches: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    reapproach_travel: np.ndarray = field(default_factory=lambda: np.zeros(0))
    shape: dict = field(default_factory=dict)
    time_split: dict = field(default_factory=dict)
    camera_corrections: dict | None = None
    vision_plain: tuple | None = None

    @classmethod
    def from_state(cls, state, world, config) -> "Trace":
        """The trace of a finished exploration from its state and records."""
        recs = state.records

        def col(name):
            return np.array([getattr(r, name) for r in recs], dtype=np.float64)

        regions = [np.asarray(r.region_correlation, dtype=np.float64).reshape(-1) for r in recs]
        width = max((len(r) for r in regions), default=0)
        return cls(mode=config.mode, scene_name=world.name, hausdorff=col("hausdorff"),
                   uncertainty=col("uncertainty"), similarity=col("similarity"), travel=col("travel"),
                   path=np.asarray(state.path), contacts=np.asarray(state.contacts), model=state.model,
                   step_time=col("step_time"), terminated=state.terminated,
                   task_covariance=np.array([r.task_covariance for r in recs], dtype=np.float64).reshape(-1, 2, 2),
                   retracted=state.retracted, robot_time=col("robot_time"),
                   final_mesh=state.surface if world.dim == 3 else None, hausdorff_touched=col("hausdorff_touched"),
                   correlation=col("correlation"),
                   correlation_interval=np.array([r.correlation_interval for r in recs],
                                                 dtype=np.float64).reshape(-1, 2),
                   taps=np.array([r.taps for r in recs], dtype=np.int64), world=getattr(world, "kind", ""),
                   evidence=None if config.evidence is None else getattr(config.evidence, "name", "custom"),
                   region_correlation=(np.stack([np.pad(r, (0, width - len(r)), constant_values=np.nan)
                                                 for r in regions]) if width else np.zeros((len(recs), 0))),
                   touch=config.touch.name, contact_distance=col("contact_distance"),
                   contact_on_body=col("contact_on_body"),
                   recoveries=np.array([r.recoveries for r in recs], dtype=np.int64), truncation=col("truncation"),
                   fit_gap=col("fit_gap"), length=col("length"), noise=col("noise"), estimate=col("estimate"),
                   reapproaches=np.array([r.reapproaches for r in recs], dtype=np.int64),
                   reapproach_travel=col("reapproach_travel"),
                   shape={name: col(name) for name in SHAPE_METRICS},
                   camera_corrections=state.camera_corrections, vision_plain=state.vision_plain)

    @property
    def n_steps(self) -> int:
        return len(self.travel)

    @property
    def has_estimate(self) -> bool | None:
        """Whether the final estimate has a surface to judge (False: the run ended with no estimate; None: the world
        did not measure it, e.g. a real robot without a reference)."""
        if not len(self.estimate) or math.isnan(self.estimate[-1]):
            return None
        return bool(self.estimate[-1])

    def contacts_on_body(self, within: float = 0.01) -> dict:
        """How many of the run's contacts were on the body: ``{"on_body": fraction touched on the body itself (NaN
        where the world cannot tell), "within": fraction within ``within`` [m] of the true surface}``."""
        d, b = np.asarray(self.contact_distance), np.asarray(self.contact_on_body)
        ok_d, ok_b = np.isfinite(d), np.isfinite(b)
        return {"on_body": float(b[ok_b].mean()) if ok_b.any() else float("nan"),
                "within": float((np.abs(d[ok_d]) <= within).mean()) if ok_d.any() else float("nan")}

    def step_time_summary(self) -> dict:
        """The planning steps' wall time [s]: ``{"median", "p95", "max"}`` over every step after the first contact
        (record 0 is the approach; plan, ingest and re-learning included, robot motion excluded); NaN without one."""
        t = np.asarray(self.step_time[1:], dtype=float)
        t = t[np.isfinite(t)]
        if not len(t):
            return {"median": math.nan, "p95": math.nan, "max": math.nan}
        return {"median": float(np.median(t)), "p95": float(np.percentile(t, 95)), "max": float(t.max())}

    def records(self) -> list[dict]:
        """Per-step records as dicts (JSON/CSV friendly), in the vocabulary of the logs and ``runs.csv``."""
        out = []
        for i in range(self.n_steps):
            row = {"object": self.scene_name, "mode": self.mode, "step": i, "travel": float(self.travel[i]),
                   "hausdorff": float(self.hausdorff[i]), "uncertainty": float(self.uncertainty[i]),
                   "similarity": float(self.similarity[i])}
            if len(self.hausdorff_touched):
                row["hausdorff_touched"] = float(self.hausdorff_touched[i])
            if len(self.estimate):
                row["estimate"] = float(self.estimate[i])
            for name, values in self.shape.items():
                row[name] = float(values[i])
            if len(self.correlation):
                row["correlation"] = float(self.correlation[i])
            if len(self.correlation_interval):
                row["correlation_lo"], row["correlation_hi"] = (float(v) for v in self.correlation_interval[i])
            if self.region_correlation.size:
                row.update({f"correlation_region_{r}": float(v) for r, v in enumerate(self.region_correlation[i])})
            if self.evidence:
                row["evidence"] = self.evidence
                row["taps"] = int(self.taps[i]) if len(self.taps) else 0
            row.update({f"contact_{a}": float(v) for a, v in zip("xyz", self.contacts[i])})
            if len(self.contact_distance):
                row["contact_distance"] = float(self.contact_distance[i])
                row["contact_on_body"] = float(self.contact_on_body[i])
            row["step_time"] = float(self.step_time[i])
            if len(self.fit_gap):
                row["fit_gap"] = float(self.fit_gap[i])
            if len(self.length):
                row["length"], row["noise"] = float(self.length[i]), float(self.noise[i])
            if len(self.robot_time):
                row["robot_time"] = float(self.robot_time[i])
            out.append(row)
        return out
