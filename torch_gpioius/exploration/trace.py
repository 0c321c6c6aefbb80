"""The record of one exploration: per-step metrics, the path, the contacts and the final model."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

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
        model: the final fitted model (``GPIOIS`` or ``GPIS``).
        step_time: `(n,)` wall time of each planning step (plan + ingest + re-learn; robot motion excluded) [s].
        terminated: why it stopped: "once-around", "travel", "max_steps", "lost-contact" or "refused: ...".
        task_covariance: `(n, 2, 2)` learned K_t per record (NaN in tactile mode).
        retracted: free-space samples removed because a later contact landed within the margin.
        sim_time: `(n,)` robot clock at each record [s].
        final_mesh: 3-D only: the last estimated inner surface within the exploration range (``trimesh``).
        hausdorff_touched: `(n,)` Hausdorff distance [m] between the *touched* pieces of {mu_in = 0} (those the
            fingertip slid along, :func:`torch_gpioius.surfaces.touched_pieces`) and the true inner surface.
        correlation: `(n,)` task correlation K_t[0,1] / sqrt(K_t[0,0] K_t[1,1]) (NaN in tactile mode).
        correlation_interval: `(n, 2)` profile-likelihood interval of the correlation (NaN where not computed).
        taps: `(n,)` cumulative number of evidence-seeking taps (``evidence="taps"``).
        world: the world's class name.
        evidence: the evidence-seeking policy ("taps") or None.
        region_correlation: `(n, R)` task correlation of each region (``regions=R``; `(n, 0)` otherwise).
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
    sim_time: np.ndarray = field(default_factory=lambda: np.zeros(0))
    final_mesh: object = None
    hausdorff_touched: np.ndarray = field(default_factory=lambda: np.zeros(0))
    correlation: np.ndarray = field(default_factory=lambda: np.zeros(0))
    correlation_interval: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    taps: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    world: str = ""
    evidence: str | None = None
    region_correlation: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))

    @property
    def n_steps(self) -> int:
        return len(self.travel)

    def records(self) -> list[dict]:
        """Per-step records as dicts (JSON/CSV friendly)."""
        out = []
        for i in range(self.n_steps):
            row = {"object": self.scene_name, "mode": self.mode, "step": i, "travel_m": float(self.travel[i]),
                   "hausdorff_m": float(self.hausdorff[i]), "uncertainty": float(self.uncertainty[i]),
                   "similarity": float(self.similarity[i])}
            if len(self.hausdorff_touched):
                row["hausdorff_touched_m"] = float(self.hausdorff_touched[i])
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
            row["step_time_s"] = float(self.step_time[i])
            if len(self.sim_time):
                row["robot_time_s"] = float(self.sim_time[i])
            out.append(row)
        return out
