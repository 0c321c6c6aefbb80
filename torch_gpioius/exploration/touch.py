"""Touch models: what one touch tells about the inner shape, as an observation batch (the point touch of the paper;
tactile patches are the same contract with many points)."""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np
import torch

from ..core.validation import as_int
from ..core.registry import Registry
from .observations import Observations, ObservationPolicy, thin_points
from .patches import PatchThinning, patch_observations
from .protocols import TouchModelBase

__all__ = ["PointTouch", "PatchTouch", "TOUCH_MODELS", "register_touch_model", "touch_model", "inside_observation",
           "contact_observations"]


def contact_observations(contact: np.ndarray, policy: ObservationPolicy, step: int, source: str) -> Observations:
    """A settled contact `(d,)` [m] as the model takes it: y = 0 on the inner task, ``policy.contact_repeats``
    times (each repetition is one more independent measurement of the same label: together one observation with a
    ``contact_repeats``-th of sigma^2)."""
    k = policy.contact_repeats
    return Observations(np.repeat(np.asarray(contact, dtype=np.float64)[None], k, axis=0), np.zeros(k),
                        np.zeros(k, np.int64), step=step, source=source)


@dataclass(frozen=True)
class PointTouch(TouchModelBase):
    """A fingertip with a force sensor (Sec. VI): the settled contact point (y = 0) and the free space it crossed
    with ``|F|`` below the contact threshold (y = 1), thinned to ``policy.free_space_spacing`` and kept
    ``policy.free_space_margin`` from every contact (docs/method-notes.md); with ``policy.touch_inside``, also a
    point that far behind the contact along the measured force's direction (y < 0, inside the body)."""

    name: str = "point"

    def observations(self, result, contacts: np.ndarray, policy: ObservationPolicy, step: int) -> Observations:
        """The batch of one touch that ended in contact at ``contacts[-1]``."""
        contact = np.asarray(contacts[-1], dtype=np.float64)
        free = thin_points(result.free_space.numpy(), policy.free_space_spacing, np.asarray(contacts),
                           policy.free_space_margin)
        return Observations.concat([contact_observations(contact, policy, step, "touch"),
                                    inside_observation(contact, result, policy, step),
                                    Observations(free, np.ones(len(free)), np.zeros(len(free), np.int64), step=step,
                                                 source="touch")])

    def describe(self) -> dict:
        return {"touch": self.name}


@dataclass
class PatchTouch(TouchModelBase):
    """A tactile pad at the fingertip (DIGIT, GelSight): each touch's patch, read at the contact
    (:func:`~torch_gpioius.exploration.patches.patch_observations`: surface points with normals, free space on the
    untouched gel), and the free space the fingertip crossed, as :class:`PointTouch` records it (kept the free-space
    margin from the contacts and from the patch's surface points).

    The model takes tens of points per step, so a visual-tactile run uses the batched engine
    (``GPIOIS(inference="batched")``) and re-learns K_t by the ``min_gain`` rule (``GPIOIS.fit``), with held-Hessian
    tracking steps in place of most re-learnings and the restarts' fixed starts on a thinned copy of the data
    (``track``, ``scout``): a step's cost then stays near one factorisation as patches pile up (docs/performance.md).

    With ``max_points``, a patch adds only its most informative points (:meth:`select`): the contact, then the
    patch's points in order of their posterior variance under the model before the touch, at most ``max_points`` in
    all and none whose variance is below ``min_variance`` of the prior variance. What a dropped point would have
    told the model is bounded by its own information gain, ``1/2 log(1 + v / sigma^2)`` nats; the sum over a touch's
    dropped points bounds what the touch lost (information gain is submodular), and every log record carries it
    (``patch_dropped``, ``patch_dropped_nats``). The model stays exact on what it keeps.

    Attributes:
        settings: the patch's thinning.
        min_gain: K_t is re-learned when the exact gradient predicts more than this [nats].
        track: move K_t by one Newton step with the last re-learning's Hessian where that raises the exact MLL and
            leaves less to gain, instead of re-learning it to convergence (``GPIOIS.fit(track=True)``); each record's
            ``fit_gap`` says what the step is predicted to leave [nats].
        scout: a restart (``restart_every``) re-learns from the warm start on all the data (a fresh Hessian for the
            tracking steps), runs its fixed starts on the inner points thinned to this many and re-learns on all the
            data again only from another basin found there (``GPIOIS.fit(scout=...)``); a re-learning from a
            correlation of 1 walks off it on the same copy. None: every start on all the data, which made restarts
            grow to 30-100 s at 1.5 m of travel.
        max_hold: a full re-learning after this many kept or tracked fits in a row (more than ``restart_every``'s
            25, so that at the defaults the restarts are the full re-learnings on schedule: 4 % of the steps).
        max_points: at most this many points of each patch enter the model (default 12; None: every point of the
            spacing thinning, the reference, whose steps grow to seconds as patches pile up: docs/results-patches.md).
        min_variance: points whose posterior variance before the touch is below this fraction of the prior variance
            are dropped (with ``max_points``; default 1 %).
        sensor: the pad (a :class:`~torch_gpioius.sensors.tactile.TactileSensor`); bound from the world's
            ``Hardware.tactile`` when the run starts if None.
    """

    settings: PatchThinning = field(default_factory=PatchThinning)
    min_gain: float = 0.1
    sensor: Any = None
    max_points: int | None = 12
    min_variance: float = 0.01
    track: bool = True
    scout: int | None = 256
    max_hold: int = 30
    name: str = "patch"
    inference: str = "batched"
    _pad: Any = field(default=None, init=False, repr=False, compare=False)   # the run's hardware pad (bind)
    last_reading: Any = field(default=None, init=False, repr=False, compare=False)   # for logs and the viewer
    _patch_rows: int = field(default=0, init=False, repr=False, compare=False)      # the last batch's patch rows
    last_dropped: tuple = field(default=(0, 0.0), init=False, repr=False, compare=False)  # (points, nats bound)

    def __post_init__(self) -> None:
        as_int(self.max_points, "PatchTouch.max_points", 1, allow_none=True)
        if isinstance(self.min_variance, bool) or not (isinstance(self.min_variance, (int, float)) and
                                                       0.0 <= self.min_variance < 1.0):
            raise ValueError(f"PatchTouch.min_variance: must be a fraction in [0, 1), got {self.min_variance!r}")
        if not isinstance(self.track, (bool, np.bool_)):
            raise ValueError(f"PatchTouch.track: must be True or False, got {self.track!r}")
        as_int(self.scout, "PatchTouch.scout", 2, allow_none=True)
        as_int(self.max_hold, "PatchTouch.max_hold", 1)

    def bind(self, hardware) -> None:
        """Take the world's pad (``hardware.tactile``) unless a sensor was given.

        Raises:
            ValueError: the world has no tactile pad.
        """
        if self.sensor is None:
            pad = getattr(hardware, "tactile", None)
            if pad is None:
                raise ValueError("touch='patch': this world's hardware has no tactile pad (Hardware.tactile); give "
                                 "PatchTouch(sensor=...) or use touch='point'")
            self._pad = pad                  # each run binds its own hardware's pad

    def fit_options(self) -> dict:
        return {"min_gain": self.min_gain, "track": bool(self.track), "scout": self.scout,
                "max_hold": int(self.max_hold)}

    def footprint(self) -> dict[str, np.ndarray]:
        """The last reading's pad for logs: ``pad_pose`` `(4, 4)` pad-to-base and ``pad_size`` `(2,)` [m] (width
        along the pad's x, height along its y); empty before the first reading."""
        r = self.last_reading
        if r is None:
            return {}
        h, w = r.depth.shape
        return {"pad_pose": np.asarray(r.pose, dtype=np.float64),
                "pad_size": np.array([w * r.calibration.pitch, h * r.calibration.pitch]),
                "patch_dropped": np.array([self.last_dropped[0]], dtype=np.int64),
                "patch_dropped_nats": np.array([self.last_dropped[1]], dtype=np.float64)}

    def select(self, model, obs: Observations) -> Observations:
        """The batch with only the patch's informative points (see the class; all of it without ``max_points``).

        Args:
            model: the model before the touch (its posterior variance of the inner task ranks the points).
            obs: the batch of :meth:`observations` (the patch's rows first, the contact its first row).

        Returns:
            The kept rows, in their order; :attr:`last_dropped` says how many went and their information bound.
        """
        from ..geometry.differential import predict_task
        from ..geometry.metrics import prior_variance

        n_patch = min(self._patch_rows, len(obs))
        if self.max_points is None or n_patch <= 1:
            self.last_dropped = (0, 0.0)
            return obs
        x0 = model.train_inputs[0]
        with torch.no_grad():
            var = predict_task(model, torch.as_tensor(obs.x[:n_patch], dtype=x0.dtype, device=x0.device), 0)[1]
        var = var.detach().cpu().numpy().clip(min=0.0)
        rel = var / prior_variance(model, 0)
        order = np.r_[0, 1 + np.argsort(-rel[1:], kind="stable")]          # the contact first, then by variance
        keep = np.zeros(len(obs), dtype=bool)
        keep[n_patch:] = True                                               # the path's free space: all of it
        chosen = [i for i in order if i == 0 or rel[i] >= self.min_variance][:self.max_points]
        keep[chosen] = True
        dropped = ~keep[:n_patch]
        self.last_dropped = (int(dropped.sum()), float(0.5 * np.log1p(var[dropped] / model.noise).sum()))
        return obs.subset(keep)

    @property
    def retraction_margin(self) -> float:
        """Free space closer than this to a new contact is retracted [m]: the patch's free-space margin (2 cm by
        default, the point touch's)."""
        return self.settings.free_margin

    def observations(self, result, contacts: np.ndarray, policy: ObservationPolicy, step: int) -> Observations:
        """The batch of one touch that ended in contact at ``contacts[-1]``: the pad's patch, then free space, then
        (with ``policy.touch_inside``) one inside point behind the fingertip's contact along the measured force, as
        :class:`PointTouch` records it (one per touch, not one per pad point)."""
        pad = self.sensor if self.sensor is not None else self._pad
        if pad is None:
            raise ValueError("PatchTouch: no tactile pad bound (bind(hardware) or PatchTouch(sensor=...))")
        reading = pad.read()
        patch = patch_observations(reading, self.settings, step)
        self.last_reading = reading
        avoid = np.concatenate([np.asarray(contacts, dtype=np.float64).reshape(-1, patch.dim), patch.x[patch.y == 0]])
        free = thin_points(result.free_space.numpy(), policy.free_space_spacing, avoid, policy.free_space_margin)
        path = Observations(free, np.ones(len(free)), np.zeros(len(free), np.int64), step=step, source="touch")
        behind = inside_observation(np.asarray(contacts[-1], dtype=np.float64), result, policy, step)
        self._patch_rows = len(patch)
        return Observations.concat([patch, path, behind], source="patch")

    def describe(self) -> dict:
        out = {"touch": self.name, "patch": asdict(self.settings), "min_gain": self.min_gain}
        # every patch is kept in logs written before the selection existed: they resume with max_points=None
        if self.max_points is not None:
            out.update(max_points=int(self.max_points), min_variance=float(self.min_variance))
        # logs written before tracking and scouted restarts re-learned in full every time: they resume with
        # track=False, scout=None, max_hold=20
        if (self.track, self.scout, self.max_hold) != (False, None, 20):
            out["relearn"] = {"track": bool(self.track), "scout": None if self.scout is None else int(self.scout),
                              "max_hold": int(self.max_hold)}
        return out


#: Touch models by name (``explore(..., touch="point")``, ``gpioius study --touch``).
TOUCH_MODELS: Registry[type] = Registry("touch model")


def register_touch_model(name: str, cls: type, *, aliases=(), description: str = "") -> type:
    """Register a touch model class (a :class:`~torch_gpioius.exploration.protocols.TouchModelBase` built without
    arguments) under ``name``: ``explore(..., touch=name)``, ``gpioius simulate3d --touch``, ``gpioius study --touch``
    and a study's run files then know it. Returns ``cls``.

    Raises:
        ValueError: ``cls`` does not subclass the base, or the name is taken by another class.
    """
    if not (isinstance(cls, type) and issubclass(cls, TouchModelBase)):
        raise ValueError(f"register_touch_model: {cls!r} is not a TouchModelBase subclass")
    TOUCH_MODELS.register(name, cls, aliases=aliases, description=description)
    return cls


register_touch_model("point", PointTouch, description="the paper's fingertip contact: a point and its force")
register_touch_model("patch", PatchTouch, description="a gel pad's depth map: a patch of surface at each contact")


def inside_observation(contact: np.ndarray, result, policy: ObservationPolicy, step: int) -> Observations:
    """At most one inner observation: the point ``policy.touch_inside`` [m] behind ``contact`` `(d,)` along the
    outward normal the force sensor measured there (``result.force_normal``), labelled
    ``policy.inside_label(touch_inside)``; none without the setting or a measured force."""
    none = Observations.empty(len(contact), step, "touch")
    if policy.touch_inside is None or result is None or not len(getattr(result, "forces", ())):
        return none
    normal = np.asarray(result.force_normal, dtype=np.float64).reshape(-1)
    if normal.shape != contact.shape:
        return none
    points, labels, _ = policy.behind_contacts(contact[None], normal[None])
    if not len(points):
        return none
    return Observations(points, labels, np.zeros(len(points), np.int64), step=step, source="touch")


def touch_model(touch) -> TouchModelBase:
    """A touch model from its name or itself: a :class:`~torch_gpioius.exploration.protocols.TouchModelBase`, or any
    object with ``observations(result, contacts, policy, step)`` alone, which gets the base's defaults (the one
    place that looks at what an object has: the exploration then calls the contract's methods).

    Raises:
        ValueError: an unknown name, an object without ``observations``, or one that writes more of the contract
            (``bind``, ``select``, ``fit_options``, ...) without subclassing the base (its methods would be passed
            over).
    """
    if touch is None:
        return PointTouch()
    if isinstance(touch, str):
        if touch not in TOUCH_MODELS:
            raise ValueError(f"touch: must be one of {TOUCH_MODELS.choices()} or a touch model, got {touch!r}")
        return TOUCH_MODELS.make(touch)
    if isinstance(touch, TouchModelBase):
        return touch
    if not callable(getattr(touch, "observations", None)):
        raise ValueError(f"touch: expected a name or an object with observations(result, contacts, policy, step), "
                         f"got {type(touch).__name__}")
    more = [m for m in ("bind", "select", "fit_options", "footprint", "retraction_margin", "inference")
            if hasattr(touch, m)]
    if more:
        raise ValueError(f"touch: {type(touch).__name__} has {', '.join(more)}: subclass "
                         "torch_gpioius.exploration.TouchModelBase so that the exploration calls them")
    return _ObservationsOnly(touch)


class _ObservationsOnly(TouchModelBase):
    """A touch given as an object with ``observations`` alone, with the base's defaults for the rest."""

    def __init__(self, touch) -> None:
        self.touch = touch
        self.name = str(getattr(touch, "name", type(touch).__name__))

    def observations(self, result, contacts, policy, step):
        return self.touch.observations(result, contacts, policy, step)

    def describe(self) -> dict:
        describe = getattr(self.touch, "describe", None)
        return describe() if callable(describe) else {"touch": self.name}
