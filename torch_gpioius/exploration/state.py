"""The public state of one exploration and its per-step record, in the one vocabulary that state, traces, logs,
``runs.csv`` and the viewer share (docs/data-format.md, "Record fields")."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import torch

from .observations import CoverGap, Observations

__all__ = ["ExplorationState", "StepRecord", "RECORD_FIELDS"]

#: The per-step values and their units: the names every layer uses (state, Trace, logs, runs.csv, viewer).
RECORD_FIELDS = {
    "step": "step number (0: the state right after the first contact)",
    "travel": "fingertip travel since the first contact [m]",
    "hausdorff": "Hausdorff distance of the whole estimate {mu_in = 0} to the true inner surface [m] (eq. 24)",
    "hausdorff_touched": "the same for the pieces of the estimate the fingertip touched [m]",
    "uncertainty": "uncertainty measure, eq. (23), relative to the prior variance",
    "chamfer": "Chamfer distance: the mean of the two mean surface-to-surface distances, estimate and truth [m]",
    "fscore_1mm": "F-score at 1 mm: harmonic mean of the estimate's and the truth's shares within 1 mm of the other",
    "fscore_5mm": "the same at 5 mm",
    "fscore_10mm": "the same at 10 mm",
    "fscore_20mm": "the same at 20 mm",
    "bias": "median signed distance of the true surface from the estimate [m]; negative: the estimate lies inside",
    "hausdorff_observed": "Hausdorff distance over the true surface within 2 cm of an observation [m]",
    "unseen": "share of the true surface (in range) more than 2 cm from every observation",
    "estimate": "1 where the estimate was measured and has a surface to judge (2-D: a closed curve; 3-D: surface in "
                "the range), 0 where it was measured and has none (no estimate), NaN where not measured",
    "similarity": "the paper's similarity K_t[0,1] / K_t[0,0] (a ratio of amplitudes)",
    "correlation": "task correlation K_t[0,1] / sqrt(K_t[0,0] K_t[1,1])",
    "correlation_interval": "its 95 % profile-likelihood interval (lo, hi)",
    "task_covariance": "the learned K_t, (2, 2)",
    "region_correlation": "task correlation of each region of a local model, (R,)",
    "step_time": "wall time of planning, ingesting and re-learning [s] (motion excluded)",
    "robot_time": "the robot's clock [s]",
    "taps": "evidence-gathering actions so far (taps)",
    "recoveries": "recoveries from a stall so far",
    "reapproaches": "re-approaches after lost contact so far",
    "reapproach_travel": "fingertip travel spent on those re-approaches so far [m] (part of travel)",
    "contact_distance": "distance of the step's contact from the true inner surface [m] (negative inside)",
    "contact_on_body": "1 if the fingertip touched the body itself at the contact, 0 if only the cover (NaN unknown)",
    "retracted": "free-space samples retracted so far",
    "truncation": "bound on the truncated outer basis' change of the Gram matrix, relative to sigma^2 (0: exact)",
    "fit_gap": "the MLL gain predicted to remain from the K_t in use to the optimum [nats]: 0 after a full "
               "re-learning; a held or tracked K_t's Newton decrement with the last re-learning's Hessian",
    "length": "the kernel's length in use [m] (the inverse multiquadric's theta, the Matern length scale; NaN for a "
              "kernel without one); it changes only where the run learns it (learn='length' or 'all')",
    "noise": "the noise variance sigma^2 in use",
}


@dataclass
class StepRecord:
    """What one step of an exploration produced (record 0: the state after the approach's first contact).

    The loop fills the motion, the observations and the model's values; recorders add what they measure (the
    ground-truth metrics, the correlation's interval) before the log writes it. Field meanings and units:
    :data:`RECORD_FIELDS`.

    Attributes (beyond :data:`RECORD_FIELDS`):
        final: whether a stop rule that needs no estimate ended the run at this step (recorders measure then).
        observations: the inner observations this step's touch added (before any evidence).
        removed: `(k,)` indices (into the training set before the step) of free space retracted for them.
        touch: the contact controller's result of the step (path, forces) or of the approach (record 0).
        evidence: ``(observations, removed, kind, path)`` of each evidence action or recovery taken after the touch
            (``path`` `(m, d)`: the positions its motion visited [m]).
    """

    step: int
    travel: float
    hausdorff: float = math.nan
    hausdorff_touched: float = math.nan
    uncertainty: float = math.nan
    estimate: float = math.nan
    chamfer: float = math.nan
    fscore_1mm: float = math.nan
    fscore_5mm: float = math.nan
    fscore_10mm: float = math.nan
    fscore_20mm: float = math.nan
    bias: float = math.nan
    hausdorff_observed: float = math.nan
    unseen: float = math.nan
    similarity: float = math.nan
    correlation: float = math.nan
    correlation_interval: tuple = (math.nan, math.nan)
    task_covariance: np.ndarray = field(default_factory=lambda: np.full((2, 2), np.nan))
    region_correlation: np.ndarray = field(default_factory=lambda: np.zeros(0))
    step_time: float = math.nan
    robot_time: float = math.nan
    taps: int = 0
    recoveries: int = 0
    reapproaches: int = 0
    reapproach_travel: float = 0.0
    retracted: int = 0
    contact_distance: float = math.nan
    contact_on_body: float = math.nan
    truncation: float = 0.0
    fit_gap: float = 0.0
    length: float = math.nan
    noise: float = math.nan
    final: bool = False
    camera_corrections: dict | None = None
    observations: Observations | None = None
    removed: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    touch: object = None
    evidence: list = field(default_factory=list)


@dataclass
class ExplorationState:
    """Everything an exploration carries from step to step (and a resume restores from a log).

    Attributes:
        model: the current model (``GPIOIS``, ``GPIS`` or ``LocalGPIOIS``).
        contacts: the contacts so far, each `(d,)` [m]; the last is where the fingertip rests.
        path: every position the fingertip occupied, each `(d,)` [m].
        travel: fingertip travel since the first contact [m].
        retracted: free-space samples retracted so far.
        previous: the last planned direction `(d,)` (the planner keeps its sense), or None.
        normal: the measured contact normal at the current contact `(d,)` (from the force), or None.
        steps: planning steps taken.
        taps: evidence actions taken; last_evidence: the step of the last one.
        recoveries: recoveries from a stall; last_recovery: the step of the last one; failed_recoveries: those in a
            row after which the run still made no progress.
        reapproaches: re-approaches after lost contact (:func:`torch_gpioius.exploration.loop.recover`);
            reapproach_travel: the travel they took [m] (counted in ``travel``).
        terminated: why the run ended (None while it runs).
        centre: centroid of the estimated inner region, from the last measurement (2-D stop rule).
        surface: the last measured estimate (2-D polylines or a 3-D mesh), or None.
        records: one :class:`StepRecord` per step, record 0 first.
        gap_check: the cover's gap as the contacts show it (:class:`CoverGap`), kept from step to step so that each
            contact's distance is computed once; rebuilt on resume, to the same values.
        captures: each camera view's capture as first taken (kept only with ``ObservationPolicy.camera_bound``);
            crop: the box the camera's cloud is cropped to.
        camera_corrections: what each view was moved by the last time the contacts corrected the captures
            (:func:`~torch_gpioius.exploration.calibration.correct_camera`), or None before.
        vision_plain: ``(x, y)`` the first capture labelled as the paper labels it, each point in the voxel it was
            measured in (no ``ray_smoothing``), where the policy smooths; None otherwise (the simple baselines are
            also scored on it: :mod:`torch_gpioius.baselines`). Not the model's.
    """

    model: object
    contacts: list = field(default_factory=list)
    path: list = field(default_factory=list)
    travel: float = 0.0
    retracted: int = 0
    previous: torch.Tensor | None = None
    normal: torch.Tensor | None = None
    steps: int = 0
    taps: int = 0
    last_evidence: int = 0
    recoveries: int = 0
    last_recovery: int = 0
    failed_recoveries: int = 0
    reapproaches: int = 0
    reapproach_travel: float = 0.0
    unconverged_fits: int = 0
    terminated: str | None = None
    centre: np.ndarray | None = None
    surface: object = None
    records: list = field(default_factory=list)
    gap_check: CoverGap = field(default_factory=CoverGap, repr=False, compare=False)
    captures: list | None = field(default=None, repr=False, compare=False)
    #: The height [m] of the table the captures' table points are held to when corrected
    #: (``ObservationPolicy.camera_table``: the contact controller's floor), or None.
    table: float | None = field(default=None, repr=False, compare=False)
    crop: np.ndarray | None = field(default=None, repr=False, compare=False)
    camera_corrections: dict | None = None
    vision_plain: tuple | None = field(default=None, repr=False, compare=False)

    @property
    def contact(self) -> np.ndarray:
        """`(d,)` the current contact [m]."""
        return self.contacts[-1]

    @property
    def dim(self) -> int:
        return len(self.contacts[-1])

    def contacts_array(self) -> np.ndarray:
        """`(k, d)` the contacts so far [m]."""
        return np.asarray(self.contacts)
