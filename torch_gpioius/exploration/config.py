"""The settings of one exploration, validated once, with the world's defaults merged in (:class:`ExploreConfig`),
and what recorders see of a run (:class:`Run`)."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
import torch

from ..core.validation import as_device, as_float, as_int
from .planning import RangePenalty
from ..kernels import InverseMultiquadricKernel, as_kernel
from ..models.estimator import LEARN, RESTART_EVERY, EstimatorSettings, EstimatorView, as_learn  # noqa: F401
from ..models.gpiois import INNER, OUTER
from .policies import evidence_policy
from .observations import Observations
from .recovery import NoProgress
from .stopping import StopRule, TravelBudget
from .touch import touch_model

__all__ = ["ExploreConfig", "Run", "MODES", "LEARN", "LEARN_SIZE", "LOOSE", "as_learn"]

MODES = ("visual-tactile", "tactile")
#: The loose estimator keywords :func:`torch_gpioius.explore` and :meth:`ExploreConfig.from_world` still read for one
#: release (``**deprecated``): the estimator's settings are one object, ``settings=EstimatorOverrides(...)``.
LOOSE = ("theta", "kernel", "noise", "policy", "learn", "restart_every")


#: The copy the length and sigma^2 are learned on: at most this many inner and outer points (evenly in arrival order).
#: 256 + 512 points cost 1.0-1.3 s a learning against 7.5 s on a 0.15 m run's 1,021 (one thread; docs/method-notes.md).
LEARN_SIZE = (256, 512)


@dataclass(frozen=True)
class ExploreConfig(EstimatorView):
    """One exploration's settings (see :func:`torch_gpioius.explore` for each): build it with :meth:`from_world`.

    Attributes:
        mode: "visual-tactile" (GPIOIS on vision + touch) or "tactile" (GPIS on touch only).
        evidence: the evidence policy (e.g. :class:`~torch_gpioius.exploration.evidence.TapPolicy`) or None.
        touch: the touch model (:class:`~torch_gpioius.exploration.touch.PointTouch` by default).
        step: alpha, the planned step [m].
        estimator: the estimator's settings (kernel, sigma^2, labels, what is learned; read through ``kernel``,
            ``lengthscale``, ``noise``, ``policy``, ``learn`` and ``restart_every``).
        max_steps: cap on planning steps (evidence actions count as steps).
        stop: the stop rules.
        penalty: C(x) of eq. (19) / (25).
        metrics_every: ground-truth metrics every k steps (and at the last); None: on the schedule alone (10, 25
            and 50 % of the travel budget, a stop, the end).
        metrics_resolution: grid of the metrics [m] (None: the world's).
        interval_every: the correlation's profile interval every k steps (None: never).
        regions: a similarity per region (``LocalGPIOIS`` with this many regions) or None.
        approach_travel: the approach gives up after this distance [m].
        stall: the no-progress rule and its recovery (:class:`~torch_gpioius.exploration.recovery.NoProgress`), or
            None to switch it off.
        outer_tol: the truncated outer basis of ``GPIOIS(outer_tol=...)`` (an approximation for thousands of
            camera points), or None (exact).
        device: where the model's data and exact arithmetic live (a ``torch.device``), or None (the CPU).
        restart_every: every this many steps K_t's re-learning also starts from fixed, data-independent values and
            keeps the best optimum (``GPIOIS.fit(multi_start=True)``), so that a warm start cannot hold it in a worse
            local optimum for the rest of the run; None: warm starts only (the first fit always multi-starts).
        learn: "task" (K_t alone, the paper's), "length" (also the kernel's length) or "all" (the length and
            sigma^2 too), on every ``restart_every``-th step, from the configured values; :data:`LEARN_SIZE` points at
            most.
    """

    mode: str
    evidence: object
    touch: object
    step: float
    estimator: EstimatorSettings
    max_steps: int
    stop: tuple
    penalty: object
    metrics_every: int | None
    metrics_resolution: float | None
    interval_every: int | None
    regions: int | None
    approach_travel: float
    stall: NoProgress | None = NoProgress()
    outer_tol: float | None = None
    device: torch.device | None = None

    @classmethod
    def from_world(cls, world, mode: str = "visual-tactile", *, settings=None, evidence=None, touch=None, step=None,
                   max_steps=None, max_travel=None, stop=None, penalty=None, metrics_every=None,
                   metrics_resolution=None, interval_every=None, regions=None, stall="default", outer_tol=None,
                   device=None, **deprecated) -> "ExploreConfig":
        """Validate the overrides and merge them with ``world.defaults`` (see :func:`torch_gpioius.explore`, whose
        parameters these are; ``**deprecated`` as its). Why this many parameters: explore's, one each.

        Raises:
            TypeError: a keyword it does not take.
            ValueError: an invalid setting (names it).
        """
        from ..models.base import kernel_for_theta
        from ..models.overrides import loose_keywords, warn_loose

        loose = loose_keywords("ExploreConfig.from_world", deprecated, LOOSE)
        restart = loose["restart_every"]
        warn_loose("ExploreConfig.from_world", 2, kernel=loose["kernel"], noise=loose["noise"],
                   policy=loose["policy"], learn=loose["learn"], restart_every=restart)
        kernel = kernel_for_theta(loose["theta"], loose["kernel"], "ExploreConfig.from_world")
        if mode not in MODES:
            raise ValueError(f"mode: must be one of {MODES}, got {mode!r}")
        evidence = evidence_policy(evidence)
        if evidence is not None and mode != "visual-tactile" and evidence.needs_vision:
            raise ValueError(f"evidence: the {evidence.name} policy is about the similarity; it needs "
                             "mode='visual-tactile'")
        if regions is not None:
            regions = as_int(regions, "regions", 1, 64)
            if mode != "visual-tactile":
                raise ValueError("regions: a similarity per region needs mode='visual-tactile'")
        touch = touch_model(touch)
        if outer_tol is not None:
            outer_tol = as_float(outer_tol, "outer_tol", positive=True)
            if mode != "visual-tactile" or regions is not None:
                raise ValueError("outer_tol: the truncated outer basis is GPIOIS's; it needs mode='visual-tactile' "
                                 "and no regions")
            inference = touch.inference
            if inference != "auto":
                raise ValueError(f"outer_tol: the {touch.name} touch uses the {inference} "
                                 "engine, which has no truncated outer basis")
        d = world.defaults
        step = as_float(d.step if step is None else step, "step", lo=1e-4, hi=0.1, positive=True, unit="m")
        estimator = _estimator(world, settings, kernel=kernel, noise=loose["noise"], policy=loose["policy"],
                               learn=loose["learn"], restart_every=restart)
        max_steps = as_int(d.max_steps if max_steps is None else max_steps, "max_steps", 0, 100_000)
        metrics_every = d.metrics_every if metrics_every is None else metrics_every
        if isinstance(metrics_every, str) and metrics_every == "schedule":
            if not any(isinstance(r, TravelBudget) for r in (d.stop if stop is None else stop)) and max_travel is None:
                raise ValueError("metrics_every='schedule': measures at fractions of a travel budget; this run has "
                                 "none (give max_travel, or a number of steps)")
            metrics_every = None                            # the schedule alone: REPORT_FRACTIONS, a stop, the end
        else:
            metrics_every = as_int(metrics_every, "metrics_every", 1, 1_000_000)
        if interval_every is not None:
            interval_every = as_int(interval_every, "interval_every", 1, 1_000_000)
        if metrics_resolution is not None:
            metrics_resolution = as_float(metrics_resolution, "metrics_resolution", lo=1e-3, hi=0.5, unit="m")
        rules = tuple(d.stop if stop is None else stop)
        if not all(isinstance(r, StopRule) for r in rules):
            raise ValueError("stop: every rule must be a torch_gpioius.exploration.StopRule")
        if max_travel is not None:
            rules = tuple(r for r in rules if not isinstance(r, TravelBudget)) + (TravelBudget(max_travel),)
        penalty = penalty if penalty is not None else world.penalty()
        if isinstance(stall, str) and stall == "default":
            stall = NoProgress()
        if stall is not None and not isinstance(stall, NoProgress):
            raise ValueError(f"stall: expected a NoProgress rule or None, got {type(stall).__name__}")
        learn = estimator.learn
        if learn != "task":
            if estimator.restart_every is None:
                raise ValueError(f"learn={learn!r}: the length and sigma^2 are learned on the restart steps; "
                                 "restart_every=None has none")
            if regions is not None:
                raise ValueError(f"learn={learn!r}: the kernel's length is learned with one similarity; "
                                 "regions has one per region (use learn='task')")
        config = cls(mode, evidence, touch, step, estimator, max_steps, rules, penalty, metrics_every,
                     metrics_resolution, interval_every, regions, float(d.approach_travel), stall, outer_tol,
                     as_device(device))
        if evidence is not None:                  # a reach: the range and budget
            box = (np.stack([penalty.lower.cpu().numpy(), penalty.upper.cpu().numpy()])
                   if isinstance(penalty, RangePenalty) else None)
            config = dataclasses.replace(config, evidence=evidence.for_run(dim=world.dim, bounds=box,
                                                                           budget=config.budget))
        return config

    # ------------------------------------------------------------------ what the loop asks of the settings
    @property
    def initial_hyperparameters(self) -> tuple[float, float]:
        """`(length [m], sigma^2)` as configured: where every learning of ``learn`` starts."""
        return float(self.estimator.kernel.length), float(self.noise)

    @property
    def uses_vision(self) -> bool:
        """Whether the camera's capture enters the model (visual-tactile)."""
        return self.mode == "visual-tactile"

    @property
    def budget(self) -> float | None:
        """The travel budget [m] of the stop rules (for progress in centimetres), or None."""
        return next((r.max_travel for r in self.stop if isinstance(r, TravelBudget)), None)

    def make_model(self, inner: Observations, outer: Observations | None):
        """The model of this mode on the first observations: GPIOIS (or LocalGPIOIS with ``regions``) on inner and
        outer ones, GPIS on the inner ones alone."""
        if not self.uses_vision:
            return self.model_for(inner.x, inner.y, inner.task)
        return self.model_for(np.concatenate([inner.x, outer.x]), np.concatenate([inner.y, outer.y]),
                              np.r_[np.full(len(inner), INNER), np.full(len(outer), OUTER)])

    def model_for(self, x: np.ndarray, y: np.ndarray, task: np.ndarray):
        """The model of this mode on observations in the given order (GPIS keeps the inner ones), made by the
        estimator's settings (:meth:`~torch_gpioius.models.estimator.EstimatorSettings.make_model`)."""
        if not self.uses_vision:
            inner = np.asarray(task) == INNER
            model = self.estimator.make_model(np.asarray(x)[inner], np.asarray(y)[inner])
        elif self.regions is not None:
            model = self.estimator.make_model(x, y, task, regions=self.regions)
        else:
            model = self.estimator.make_model(x, y, task, inference=self.touch.inference, outer_tol=self.outer_tol)
        return model.to_device(self.device)

    def _policy_record(self) -> dict:
        """The observation policy for the header; the inside-point settings, ``cover_offset``,
        ``vision_inside_deep``, ``cover_gap_field``, ``cover_carry``, ``cover_uneven_field``, ``cover_even``,
        ``camera_bound``, ``contact_repeats`` and ``inside_halvings`` only when set, so that logs written before they
        existed still resume."""
        out = dataclasses.asdict(self.policy)
        for key in ("touch_inside", "vision_inside", "vision_inside_gap", "camera_bound", "cover_even"):
            if out[key] is None:
                del out[key]
        # cover_offset since 2026-11-27, vision_inside_deep and cover_gap_field since -29, cover_carry since 12-01,
        # cover_uneven_field since 12-02
        for key in ("cover_offset", "vision_inside_deep", "cover_gap_field", "cover_carry", "cover_uneven_field"):
            if not out[key]:
                del out[key]
        if out.get("camera_bound") is None:        # camera_table: said only where a bound makes it act
            del out["camera_table"]
        if out["contact_repeats"] == 1:             # (since 2026-11-30)
            del out["contact_repeats"]
        if out["inside_halvings"] == 0:             # (since 2026-12-01)
            del out["inside_halvings"]
        return out

    def describe(self) -> dict:
        """JSON-able settings for a log's header (resume compares them); ``estimator`` holds the estimator's
        settings whole (:meth:`~torch_gpioius.models.estimator.EstimatorSettings.to_dict`)."""
        kernel = self.estimator.kernel.describe()
        theta = self.lengthscale if isinstance(self.kernel, InverseMultiquadricKernel) else None  # earlier logs' key
        evidence = None if self.evidence is None else self.evidence.name
        out = {"mode": self.mode, "evidence": evidence, "touch": self.touch.name,
               "step_length": self.step, "theta": theta, "kernel": kernel,
               "noise": float(self.noise), "max_steps": self.max_steps,
               "stop": [r.describe() for r in self.stop], "metrics_every": self.metrics_every,
               "metrics_resolution": self.metrics_resolution, "interval_every": self.interval_every,
               "regions": self.regions, "policy": self._policy_record(),
               "penalty": type(self.penalty).__name__,
               "stall": None if self.stall is None else self.stall.describe()}
        if self.outer_tol is not None:            # only when set: logs written before it existed still resume
            out["outer_tol"] = self.outer_tol
        out["restart_every"] = self.restart_every
        if self.learn != "task":                  # only when set: logs written before it existed still resume
            out["learn"] = self.learn
        if self.evidence is not None:
            out["evidence_policy"] = self.evidence.describe()
        out["estimator"] = self.estimator.to_dict()
        return out


def _estimator(world, settings, *, kernel, noise, policy, learn, restart_every) -> EstimatorSettings:
    """The estimator's settings of one exploration: ``settings`` (an :class:`EstimatorSettings` or a preset's name;
    a preset's voxel and length rules sized to the world's object; an
    :class:`~torch_gpioius.models.overrides.EstimatorOverrides`: the world's own with those changes) or the world's
    own, with the single settings given beside it in their place (one resolver,
    :class:`~torch_gpioius.models.overrides.EstimatorOverrides`, checks and applies them)."""
    from ..models.overrides import KEEP, EstimatorOverrides

    changes = EstimatorOverrides()
    if isinstance(settings, EstimatorOverrides):            # the world's own, with these changes
        changes, settings = settings, None
    est = world.defaults.estimator if settings is None else EstimatorSettings.of(settings)
    if est.sized_to_object and est is not world.defaults.estimator:
        extent = world.object_extent
        if extent is not None:
            est = est.for_extent(extent)
    if kernel is not None:
        kernel = as_kernel(kernel)                   # an ExactKernel, or a TypeError naming what it is
    keep = isinstance(restart_every, str) and restart_every == "default"
    loose = EstimatorOverrides(kernel=kernel, noise=noise, policy=policy, learn=learn,
                               restart_every=KEEP if keep else restart_every)
    return changes.merged(loose).apply(est)


@dataclass
class Run:
    """What the loop and its recorders share about one run: the world, its hardware and the settings.

    Attributes:
        world: the :class:`~torch_gpioius.exploration.world.World`.
        hardware: its :class:`~torch_gpioius.exploration.world.Hardware` for this run.
        config: the :class:`ExploreConfig`.
        resumed: whether the run continues from a log.
    """

    world: object
    hardware: object
    config: ExploreConfig
    resumed: bool = False

    @property
    def dim(self) -> int:
        return int(self.world.dim)

