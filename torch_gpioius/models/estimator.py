"""The estimator's settings in one object: what turns observations into a model and its labels.

:class:`EstimatorSettings` holds the kernel (which carries its own length scale), the noise ``sigma^2``, the labelling
policy (:class:`~torch_gpioius.models.labels.ObservationPolicy`: free space near and far, the inside points behind
touches and behind the seen surface with their depth, the cover-gap retraction, the camera's voxels), the rules that
size the voxels and the kernel's length to the object, what is learned and the restart schedule of K_t's fit. Every
path that makes a model takes one: an exploration in any world, ``gpioius fit`` on a user's files, a bag import,
``replay``, ``export`` and the studies. A world suggests one for its objects (the robot study's objects E-H ran the
paper's; a user's mesh gets the default), but the object lives here, in the model layer, so that a user's own data
meets the same settings as a simulated run.

Presets (:func:`EstimatorSettings.preset`):

* ``"default"``: what measured best on shapes nobody tuned to (docs/method-notes.md sections 12-15): a Matérn-5/2 of
  length scale a fifth of the object's largest extent (4-10 cm; :class:`LengthRule`; 10 cm where the object's size
  is unknown), sigma^2 = 0.08, the camera's points averaged in voxels a tenth of the object's largest extent
  (2-5 cm), each in the voxel its depth smoothed along the camera's rays (over 24 of them) lies in, a second
  free-space point 10 cm in front of each seen point, inside points 2 cm behind every contact and every seen point,
  and those behind the seen surface retracted once the touches show the cover standing more than 3 cm off the body,
  unless their gaps agree: then the outer task's prior mean stands for the gap they measure (corrected, once set,
  for the transfer K_t learned, so that away from the touches the estimate lies the gap below the cover; section 31)
  and the camera's inside points are continued down to it, for as long as they agree (one gap while the touches
  agree, section 27); once they stop agreeing, a field of their gaps a place at a time instead (section 32);
  each contact counted four times (a fingertip's contact with a quarter of the camera's noise); an inside point
  contradicted on a part thinner than its depth tried again at 1 cm and 5 mm;
* ``"paper"``: the paper's robot experiment (Sec. VI): the inverse multiquadric of theta = 0.15 m, sigma^2 = 0.08,
  5 cm voxels, no inside points;
* ``"paper-2d"``: the paper's 2-D simulation (Sec. V): the inverse multiquadric of theta = 0.1 m, sigma^2 = 0.006;
* ``"gap"`` and ``"gapfield"`` (experiments, not the default): ``"default"`` with the one gap taken whether the
  touches' gaps agree or not, or a field of gaps (:meth:`EstimatorSettings.gap`, :meth:`EstimatorSettings.gap_field`).

:meth:`EstimatorSettings.to_dict` and :meth:`EstimatorSettings.from_dict` give the plain dict that logs, datasets,
checkpoints, run records and scene files store.
"""

from __future__ import annotations

import copy
import dataclasses
from dataclasses import dataclass

import numpy as np

from ..core.validation import as_float, as_int, as_noise
from ..kernels import (ExactKernel, InverseMultiquadricKernel, KernelChoice, Matern52, as_kernel, from_description,
                       kernel_named)
from .labels import ObservationPolicy

__all__ = ["EstimatorView", "EstimatorSettings", "VoxelRule", "LengthRule", "PRESETS", "LEARN", "as_learn",
           "RESTART_EVERY"]

#: What an estimator learns besides K_t: "task" (K_t alone, the paper's Sec. IV-A), "length" (the kernel's length
#: scale and K_t) or "all" (the length, sigma^2 and K_t), by the exact marginal likelihood.
LEARN = ("task", "length", "all")

#: Default of ``restart_every``: K_t's re-learning also tries fixed starts every this many steps (3 Newton runs from
#: far-off starts besides the warm one: 250-270 ms against 1-2 ms at 34 inner and 731 outer points; docs/theory.md,
#: "Local optima of K_t"). Every 25th step is 4 % of the steps, so the 95th percentile of the step is never a restart.
RESTART_EVERY = 25


def as_learn(value) -> str:
    """``value`` if it names what an estimator learns (:data:`LEARN`).

    Raises:
        ValueError: anything else, naming the choices.
    """
    if not isinstance(value, str) or value not in LEARN:
        raise ValueError(f"learn: must be one of {LEARN}, got {value!r}")
    return value


def _check_rule(rule, name: str, lo: float, hi: float) -> None:
    """Refuse a size rule (``fraction``, ``lo``, ``hi``) whose fraction is outside (0, 1] or whose bounds [m] are
    not ordered within ``[lo, hi]``, naming ``name`` and the field."""
    as_float(rule.fraction, f"{name}.fraction", lo=1e-3, hi=1.0, positive=True)
    as_float(rule.lo, f"{name}.lo", lo=lo, hi=hi, positive=True, unit="m")
    as_float(rule.hi, f"{name}.hi", lo=lo, hi=hi, positive=True, unit="m")
    if not rule.lo <= rule.hi:
        raise ValueError(f"{name}: lo ({rule.lo:g} m) must not exceed hi ({rule.hi:g} m)")


def _sized(rule, extent: float) -> float:
    """``rule.fraction`` of ``extent`` [m] clipped to ``[rule.lo, rule.hi]``, rounded to 0.1 mm."""
    extent = as_float(extent, "extent", positive=True, unit="m")
    return round(float(np.clip(extent * rule.fraction, rule.lo, rule.hi)), 4)


@dataclass(frozen=True)
class VoxelRule:
    """The camera's voxel edge from the object's size: ``fraction`` of its largest extent, clipped to ``[lo, hi]``
    [m], rounded to 0.1 mm. The paper's 5 cm voxels were sized for a torso and leave a 15 cm body a handful of outer
    points; a tenth of the body keeps about ten across any object (docs/method-notes.md).

    Raises:
        ValueError: a fraction outside (0, 1], or bounds not ordered within the voxels' range.
    """

    fraction: float = 0.1
    lo: float = 0.02
    hi: float = 0.05

    def __post_init__(self) -> None:
        from .labels import MAX_VOXEL

        _check_rule(self, "voxel_rule", 1e-4, MAX_VOXEL)

    def voxel(self, extent: float) -> float:
        """The voxel edge [m] for an object whose largest extent is ``extent`` [m]."""
        return _sized(self, extent)


@dataclass(frozen=True)
class LengthRule:
    """The kernel's length scale from the object's size: ``fraction`` of its largest extent, clipped to ``[lo, hi]``
    [m], rounded to 0.1 mm. The default is two voxels of :class:`VoxelRule`'s: 4 cm up to a 20 cm body, 10 cm from
    half a metre on (the robot study's torsos keep the 10 cm they ran with). A fixed 10 cm smoothed a 15-25 cm
    body's necks, limbs, ears and corners into the estimate: on the object-set benchmark's 200 such objects under
    tight covers the rule lowered the median Chamfer distance from 0.66 to 0.44 cm and raised the F-score at 1 cm
    from 0.82 to 0.91, and on users' files it met an F-score of 0.8 on 29 of 30 bodies where 10 cm met it on 24
    (docs/results-benchmark.md "The kernel's length", docs/results-own-data.md). Its cost: under covers standing
    about one length off a small body the outer shape looks less like the body (wide covers, 0.81 -> 0.95 cm); give
    the kernel's length there. A length shorter than the voxels would leave the outer task's points uncorrelated,
    hence the tie.

    Raises:
        ValueError: a fraction outside (0, 1], or bounds not ordered within the kernels' lengths.
    """

    fraction: float = 0.2
    lo: float = 0.04
    hi: float = 0.10

    def __post_init__(self) -> None:
        from ..core.tolerances import tol

        _check_rule(self, "length_rule", *tol.theta_range)

    def length(self, extent: float) -> float:
        """The kernel's length scale [m] for an object whose largest extent is ``extent`` [m]."""
        return _sized(self, extent)


#: The labels' changes of the one gap taken whatever the touches' spread (:meth:`EstimatorSettings.gap`): the default
#: takes it only while they agree (:data:`COVER_EVEN`).
GAP_LABELS = {"cover_offset": True, "vision_inside_deep": True, "cover_even": None, "cover_uneven_field": False}
#: ... and of that gap a place at a time (:meth:`EstimatorSettings.gap_field`).
GAP_FIELD_LABELS = {**GAP_LABELS, "cover_gap_field": True}


@dataclass(frozen=True, eq=False)
class EstimatorSettings:
    """Everything that turns observations into a model and labels (see the module docstring).

    Attributes:
        kernel: an :class:`~torch_gpioius.kernels.ExactKernel`, carrying its own length scale; each model gets a copy.
        noise: sigma^2 on the Gram matrix's diagonal (eq. 12).
        labels: the labelling policy (free space, inside points, cover-gap retraction, voxels, crop).
        voxel_rule: sizes ``labels.voxel`` to the object (:meth:`for_extent`), or None: ``labels.voxel`` as it is.
        length_rule: sizes the kernel's length scale to the object (:meth:`for_extent`), or None: the kernel's as it
            is. Giving another kernel (:meth:`replace`) drops it: the kernel then carries the length asked for.
        learn: "task", "length" or "all" (:data:`LEARN`).
        restart_every: K_t's fit also starts from fixed values every this many steps of an exploration (None: warm
            starts only; a fit on files always does).
        name: the preset it came from ("default", "paper", "paper-2d", "gap", "gapfield"), or "custom" once
            changed.
    """

    kernel: ExactKernel
    noise: float
    labels: ObservationPolicy = dataclasses.field(default_factory=ObservationPolicy)
    voxel_rule: VoxelRule | None = None
    length_rule: LengthRule | None = None
    learn: str = "task"
    restart_every: int | None = RESTART_EVERY
    name: str = "custom"

    def __post_init__(self) -> None:
        object.__setattr__(self, "kernel", as_kernel(self.kernel))
        object.__setattr__(self, "noise", as_noise(self.noise))
        if not isinstance(self.labels, ObservationPolicy):
            raise ValueError(f"labels: expected an ObservationPolicy, got {type(self.labels).__name__}")
        if self.voxel_rule is not None and not isinstance(self.voxel_rule, VoxelRule):
            raise ValueError(f"voxel_rule: expected a VoxelRule or None, got {type(self.voxel_rule).__name__}")
        if self.length_rule is not None:
            if not isinstance(self.length_rule, LengthRule):
                raise ValueError(f"length_rule: expected a LengthRule or None, got {type(self.length_rule).__name__}")
            if not self.kernel.learnable_length:
                raise ValueError(f"length_rule: the {type(self.kernel).__name__} kernel has no length to size")
        as_learn(self.learn)
        if self.learn != "task" and not self.kernel.learnable_length:
            raise ValueError(f"learn={self.learn!r}: the {type(self.kernel).__name__} kernel has no learnable length")
        if self.restart_every is not None:
            object.__setattr__(self, "restart_every", as_int(self.restart_every, "restart_every", 1, 1_000_000))
        if not isinstance(self.name, str) or not self.name:
            raise ValueError(f"name: expected a non-empty string, got {self.name!r}")

    # ------------------------------------------------------------------ presets
    @classmethod
    def preset(cls, name: str) -> "EstimatorSettings":
        """A named preset: "default", "paper" or "paper-2d" (:data:`PRESETS`; see the module docstring).

        Raises:
            ValueError: an unknown name, naming the choices.
        """
        if name not in PRESETS:
            raise ValueError(f"settings: must be one of {tuple(PRESETS)}, got {name!r}")
        return PRESETS[name]()

    @classmethod
    def of(cls, settings) -> "EstimatorSettings":
        """``settings`` itself, or the preset it names (what every path that takes settings accepts).

        Raises:
            ValueError: an unknown preset, or anything else (names its type).
        """
        if isinstance(settings, EstimatorSettings):
            return settings
        if isinstance(settings, str):
            return cls.preset(settings)
        raise ValueError(f"settings: expected EstimatorSettings or a preset's name, got {type(settings).__name__}")

    @classmethod
    def default(cls) -> "EstimatorSettings":
        """This library's settings for a user's object (see the module docstring)."""
        labels = ObservationPolicy(crop_margin=0.15, vision_free_far=0.10, touch_inside=INSIDE_DEPTH,
                                   vision_inside=INSIDE_DEPTH, vision_inside_gap=COVER_GAP_LIMIT, voxel=0.05,
                                   ray_smoothing=RAY_NEIGHBOURS, contact_repeats=CONTACT_REPEATS,
                                   inside_halvings=INSIDE_HALVINGS, cover_offset=True, vision_inside_deep=True,
                                   cover_even=COVER_EVEN, cover_carry=True, cover_uneven_field=True)
        return cls(Matern52(lengthscale=0.1), 0.08, labels, VoxelRule(), LengthRule(), name="default")

    @classmethod
    def paper(cls) -> "EstimatorSettings":
        """The paper's robot experiment (Sec. VI)."""
        return cls(InverseMultiquadricKernel(lengthscale=0.15), 0.08, ObservationPolicy(voxel=0.05, crop_margin=0.15),
                   name="paper")

    @classmethod
    def gap(cls) -> "EstimatorSettings":
        """:meth:`default` with the one gap taken whether the touches agree on it or not (an experiment,
        :data:`GAP_LABELS`): past the 3 cm cover gap the outer mean stands for the gap the touches measure and the
        camera's inside points are continued down to it, for the rest of the run (docs/method-notes.md sections
        16-17 and 26; the 3-D worlds' settings "gap"). The default does this only while the contacts' gaps agree
        (``labels.cover_even``, section 27); for a cover known to stand off evenly (a foam sleeve, a padded case)."""
        return cls.default().replace(labels=GAP_LABELS, name="gap")

    @classmethod
    def gap_field(cls) -> "EstimatorSettings":
        """:meth:`gap` a place at a time (an experiment, :data:`GAP_FIELD_LABELS`): the outer mean from a field of
        the contacts' gaps (:class:`~torch_gpioius.models.gapfield.GapField`; docs/method-notes.md section 18; the
        3-D worlds' settings "gapfield")."""
        return cls.default().replace(labels=GAP_FIELD_LABELS, name="gapfield")

    @classmethod
    def paper_2d(cls) -> "EstimatorSettings":
        """The paper's 2-D simulation (Sec. V)."""
        return cls(InverseMultiquadricKernel(lengthscale=0.1), 0.006, ObservationPolicy(), name="paper-2d")

    # ------------------------------------------------------------------ derived settings
    @property
    def lengthscale(self) -> float | None:
        """The kernel's length scale [m] (None for a kernel without one)."""
        try:
            return float(self.kernel.length)
        except TypeError:
            return None

    def replace(self, **changes) -> "EstimatorSettings":
        """A copy with ``changes`` (field names; ``labels`` may also be given as a dict of policy fields to change).
        It is named "custom" unless ``name`` is among the changes. A new ``kernel`` drops the length rule unless
        ``length_rule`` is among the changes: the kernel given carries the length asked for."""
        if "kernel" in changes:
            changes.setdefault("length_rule", None)
        if isinstance(changes.get("labels"), dict):
            changes["labels"] = dataclasses.replace(self.labels, **changes["labels"])
        changes.setdefault("name", "custom")
        return dataclasses.replace(self, **changes)

    @property
    def sized_to_object(self) -> bool:
        """Whether :meth:`for_extent` changes anything: a voxel rule or a length rule is held."""
        return self.voxel_rule is not None or self.length_rule is not None

    def for_extent(self, extent: float) -> "EstimatorSettings":
        """These settings with the voxel rule and the length rule applied to an object whose largest extent is
        ``extent`` [m] (the body's in a simulated world, the camera's clouds, or the contacts without a cloud, for a
        user's files); unchanged without a rule. The rules stay held (a record shows how the values came), and
        applying them again to the same extent changes nothing.

        Raises:
            ValueError: an extent that is not a finite positive number.
        """
        changes = {}
        if self.voxel_rule is not None:
            voxel = self.voxel_rule.voxel(extent)
            if voxel != self.labels.voxel:
                changes["labels"] = dataclasses.replace(self.labels, voxel=voxel)
        if self.length_rule is not None:
            length = self.length_rule.length(extent)
            if length != self.lengthscale:
                changes["kernel"] = KernelChoice(lengthscale=length).apply(self.kernel)
        return dataclasses.replace(self, **changes) if changes else self

    def with_kernel(self, choice) -> "EstimatorSettings":
        """These settings with a kernel asked for by name and length (a
        :class:`~torch_gpioius.kernels.KernelChoice`; an empty one: themselves): a length given replaces the length
        rule, a name alone keeps it (the new kernel then gets the rule's length from :meth:`for_extent`).

        Raises:
            ValueError: an unknown kernel or a bad length (names it); a name alone for a kernel without a length while
                a length rule is held.
        """
        if not isinstance(choice, KernelChoice):
            raise ValueError(f"kernel: expected a KernelChoice, got {type(choice).__name__}")
        if not choice:
            return self
        rule = self.length_rule if choice.lengthscale is None else None
        return self.replace(kernel=choice.apply(self.kernel), length_rule=rule)

    def with_voxel(self, voxel: float) -> "EstimatorSettings":
        """These settings with a fixed voxel edge [m] (0: every camera point), the rule dropped."""
        return self.replace(labels=self.labels.with_voxel(voxel), voxel_rule=None)

    def new_kernel(self) -> ExactKernel:
        """A copy of the kernel for one model (a GPyTorch module belongs to one model)."""
        return copy.deepcopy(self.kernel)

    def make_model(self, x, y, task=None, *, noise: float | None = None, kernel: ExactKernel | None = None,
                   regions: int | None = None, **kwargs):
        """The model these settings make on observations `(n, d)` [m] with labels `(n,)`: every model the package
        builds comes from here (an exploration's, a fit's on a dataset, a replayed step's).

        A :class:`~torch_gpioius.models.gpiois.GPIOIS` when ``task`` `(n,)` holds outer (task 1) observations (a
        :class:`~torch_gpioius.models.local.LocalGPIOIS` of ``regions`` regions when given; before the first touch,
        the camera's alone), a :class:`~torch_gpioius.models.gpis.GPIS` on the inner (task 0) observations otherwise.
        ``noise`` and ``kernel`` replace the settings' for this model (a value a run learned, a caller's kernel; the
        kernel is used as given, the settings' is copied); ``kwargs`` go to the model (``inference``, ``outer_tol``,
        ``task_covariance``, ...).

        Raises:
            ValueError: ``regions`` without the camera's observations, or what the model refuses (names it).
        """
        from .gpiois import GPIOIS
        from .gpis import GPIS

        x, y = np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64)
        noise = self.noise if noise is None else noise
        if kernel is None and kwargs.get("theta") is None:      # theta=: the models' deprecated alias, as given
            kernel = self.new_kernel()
        if task is not None:
            task = np.asarray(task)
            if (task == 1).any():               # outer observations: the two-task model (before any touch too)
                if regions is not None:
                    from .local import LocalGPIOIS

                    return LocalGPIOIS(x, y, task, regions=regions, noise=noise, kernel=kernel, **kwargs)
                return GPIOIS(x, y, task, noise=noise, kernel=kernel, **kwargs)
            x, y = x[task == 0], y[task == 0]
        if regions is not None:
            raise ValueError("regions: a similarity per region needs the camera's (outer) observations")
        return GPIS(x, y, noise=noise, kernel=kernel, **kwargs)

    # ------------------------------------------------------------------ as plain data
    def to_dict(self) -> dict:
        """The settings as plain, JSON-able data (what logs, datasets, checkpoints, run records and scene files
        store)."""
        return {"name": self.name, "kernel": self.kernel.describe(), "noise": float(self.noise),
                "labels": dataclasses.asdict(self.labels),
                "voxel_rule": None if self.voxel_rule is None else dataclasses.asdict(self.voxel_rule),
                "length_rule": None if self.length_rule is None else dataclasses.asdict(self.length_rule),
                "learn": self.learn, "restart_every": self.restart_every}

    @classmethod
    def from_dict(cls, data: dict) -> "EstimatorSettings":
        """Settings from :meth:`to_dict`'s data, or a partial dict on top of a preset: ``{"preset": "default",
        "noise": 0.02, "labels": {"voxel": 0.03}}``. ``kernel`` may be a
        description (``{"kernel": "Matern52", "lengthscale": 0.1}``) or a registered name with ``lengthscale``.

        Raises:
            ValueError: unknown keys or values (each named).
        """
        if not isinstance(data, dict):
            raise ValueError(f"estimator settings: expected a table of settings, got {type(data).__name__}")
        known = {"name", "preset", "kernel", "lengthscale", "noise", "labels", "voxel_rule", "length_rule", "learn",
                 "restart_every"}
        unknown = sorted(set(data) - known)
        if unknown:
            raise ValueError(f"estimator settings: unknown key(s) {unknown}; allowed {sorted(known)}")
        full = {"kernel", "noise", "labels"} <= set(data) and "preset" not in data     # to_dict's whole form
        base_name = None if full else data.get("preset", data.get("name") if data.get("name") in PRESETS else None)
        settings = cls.preset(base_name) if base_name is not None else None
        kernel = data.get("kernel")
        if isinstance(kernel, str):
            kernel = kernel_named(kernel, data.get("lengthscale"))
        elif isinstance(kernel, dict):
            kernel = from_description(kernel)
        elif kernel is not None:
            raise ValueError(f"kernel: expected a name or a description, got {kernel!r}")
        if kernel is None and data.get("lengthscale") is not None:
            if settings is None:
                raise ValueError("lengthscale: give the kernel (or a preset) it belongs to")
            kernel = KernelChoice(lengthscale=data["lengthscale"]).apply(settings.kernel)
        labels = data.get("labels")
        if labels is not None and not isinstance(labels, dict):
            raise ValueError(f"labels: expected a table of ObservationPolicy fields, got {labels!r}")
        fields = {f.name for f in dataclasses.fields(ObservationPolicy)}
        if labels is not None and set(labels) - fields:
            raise ValueError(f"labels: unknown field(s) {sorted(set(labels) - fields)}; allowed {sorted(fields)}")
        rule = _rule(data, "voxel_rule", VoxelRule)
        length_rule = _rule(data, "length_rule", LengthRule)
        try:
            if settings is None:
                if kernel is None or "noise" not in data:
                    raise ValueError("estimator settings: without a preset, give kernel and noise")
                return cls(kernel, data["noise"], ObservationPolicy(**(labels or {})),
                           voxel_rule=None if rule is ... else rule,
                           length_rule=None if length_rule is ... else length_rule, learn=data.get("learn", "task"),
                           restart_every=data.get("restart_every", RESTART_EVERY), name=data.get("name") or "custom")
            # a preset with changes: its own name only when nothing changed
            changes = {}
            if kernel is not None:
                changes["kernel"] = kernel
                changes["length_rule"] = None         # the length given, not the preset's rule
            if length_rule is not ...:
                changes["length_rule"] = length_rule
            for key in ("noise", "learn", "restart_every"):
                if key in data:
                    changes[key] = data[key]
            if labels:
                changes["labels"] = dataclasses.replace(settings.labels, **labels)
            if rule is not ...:
                changes["voxel_rule"] = rule
            if not changes:
                return settings
            name = data.get("name") if data.get("name") and data.get("name") not in PRESETS else "custom"
            return dataclasses.replace(settings, **changes, name=name)
        except TypeError as exc:
            raise ValueError(f"estimator settings: {exc}") from None

    @classmethod
    def of_record(cls, meta: dict) -> "EstimatorSettings":
        """The settings a record was made with (a log's, a dataset's or a run folder's header): its ``estimator``
        (:meth:`to_dict`'s form), else, for records written before the settings were recorded whole, the kernel it
        names (``kernel``, else the inverse multiquadric of ``theta``, else of 0.1 m) and its ``noise`` (else the
        paper's 2-D 0.006) with the paper's labels: the one reading of old records that replay, export, the viewer
        and a dataset's model share.

        Raises:
            ValueError: settings, a kernel or a noise the record holds that cannot be read (names which).
        """
        from ..kernels import kernel_of_record

        if not isinstance(meta, dict):
            raise ValueError(f"record: expected a header's fields, got {type(meta).__name__}")
        if isinstance(meta.get("estimator"), dict):
            try:
                return cls.from_dict(meta["estimator"])
            except ValueError as exc:
                raise ValueError(f"the header's estimator settings: {exc}") from None
        try:
            kernel = kernel_of_record(meta)
        except ValueError as exc:
            raise ValueError(f"the header's kernel: {exc}") from None
        try:
            return cls(kernel, meta.get("noise") or 0.006, ObservationPolicy(), name="custom")
        except ValueError as exc:
            raise ValueError(f"the header's noise: {exc}") from None

    # ------------------------------------------------------------------ reading
    def __eq__(self, other) -> bool:
        return isinstance(other, EstimatorSettings) and self.to_dict() == other.to_dict()

    def __hash__(self) -> int:
        return hash(repr(sorted(self.to_dict().items(), key=lambda kv: kv[0])))

    def summary(self) -> str:
        """One line of what these settings are (``gpioius fit`` prints it)."""
        p = self.labels
        inside = ("no inside points" if not (p.touch_inside or p.vision_inside) else
                  f"inside points {_cm(p.touch_inside)} behind contacts, {_cm(p.vision_inside)} behind the seen "
                  f"surface" + (f" ({_past_gap(p)})" if p.vision_inside_gap
                                else ""))
        rule = self.voxel_rule
        voxel = (f"voxels a {_fraction(rule.fraction)} of the object ({_cm(rule.lo)}-{_cm(rule.hi)})"
                 if rule is not None else f"{_cm(p.voxel)} voxels" if p.voxel else "every camera point")
        if p.ray_smoothing:
            voxel += f" chosen by depths smoothed along {p.ray_smoothing} rays"
        if p.contact_repeats > 1:
            inside += f", each contact {p.contact_repeats} times (sigma^2 / {p.contact_repeats})"
        if p.inside_halvings:
            inside += f", on thin parts at half the depth (up to {p.inside_halvings} times)"
        free = f"free space {_cm(p.vision_free_offset)}" + (f" and {_cm(p.vision_free_far)}" if p.vision_free_far
                                                               else "") + " in front of the seen surface"
        length = ("" if self.length_rule is None else f" (a {_fraction(self.length_rule.fraction)} of the object, "
                  f"{_cm(self.length_rule.lo)}-{_cm(self.length_rule.hi)})")
        return (f"settings {self.name}: {self.kernel!r}{length}, sigma^2 = {self.noise:g}, {voxel}, {free}, {inside}; "
                f"learns {_LEARNS[self.learn]}")

    def __repr__(self) -> str:
        return f"EstimatorSettings({self.summary()})"


def _rule(data: dict, key: str, cls):
    """``data[key]`` as a ``cls`` rule (fraction, lo, hi), None, or ``...`` when absent.

    Raises:
        ValueError: anything but such a table or None (names the key).
    """
    rule = data.get(key, ...)
    if rule is ... or rule is None:
        return rule
    if not isinstance(rule, dict) or set(rule) - {"fraction", "lo", "hi"}:
        raise ValueError(f"{key}: expected fraction, lo and hi, got {rule!r}")
    return cls(**rule)


_LEARNS = {"task": "K_t", "length": "K_t and the kernel's length scale", "all": "K_t, the length scale and sigma^2"}


def _fraction(f: float) -> str:
    return {0.1: "tenth", 0.2: "fifth", 0.25: "quarter", 0.5: "half"}.get(f, f"{f:g}")


def _cm(v) -> str:
    return "none" if v is None else f"{100 * float(v):g} cm"


class EstimatorView:
    """Read-through properties of a settings object that holds an ``estimator`` (:class:`EstimatorSettings`): a
    world's defaults and one exploration's configuration read the estimator's parts by the same names."""

    estimator: EstimatorSettings

    @property
    def kernel(self) -> ExactKernel:
        """The kernel (it carries its own length scale)."""
        return self.estimator.kernel

    @property
    def lengthscale(self) -> float | None:
        """The kernel's length scale [m] (None for a kernel without one)."""
        return self.estimator.lengthscale

    @property
    def noise(self) -> float:
        """sigma^2."""
        return self.estimator.noise

    @property
    def policy(self) -> ObservationPolicy:
        """The labels (:class:`~torch_gpioius.models.labels.ObservationPolicy`)."""
        return self.estimator.labels

    @property
    def learn(self) -> str:
        """What each re-learning learns: "task", "length" or "all"."""
        return self.estimator.learn

    @property
    def restart_every(self) -> int | None:
        """The K_t fit's restart schedule (contacts between restarts; None: never)."""
        return self.estimator.restart_every


#: Depth [m] of the default inside points behind contacts and seen points.
INSIDE_DEPTH = 0.02

#: The cover's gap [m] beyond which the touches retract the camera's inside points (``vision_inside_gap``): 1.5 times
#: their depth. Measured with ``cover_gap`` at every step of the real shapes' runs: 0.6-1.6 cm under the tight covers
#: (8 mm) of the bunny, duck and teddy, up to 2.8 cm under the mug's (its rim and handle), 3.9-5.3 cm under the wide
#: ones (4 cm) (docs/method-notes.md section 13).
COVER_GAP_LIMIT = 0.03

#: Rays over which the default smooths each capture's depth to choose each seen point's voxel
#: (``ObservationPolicy.ray_smoothing``): with the Kinect's noise tripled it took the median Chamfer distance on 20
#: blobs from 0.92 to 0.53 cm and on 20 primitives from 0.53 to 0.41 cm, and left the calibrated runs of objects 0-99
#: as they were (docs/results-benchmark.md "The camera's other errors").
RAY_NEIGHBOURS = 24

#: Times the default counts each contact (``ObservationPolicy.contact_repeats``): one observation with a quarter of
#: the camera's sigma^2. Chosen offline on objects 100-119 of both families (the final data of tight-cover runs refitted
#: with the touches' noise at 0.005-0.04 against the camera's 0.08: a quarter was closer than one noise on the most of
#: both) and judged in the loop on objects 0-99 (tight covers: the primitives 0.32 -> 0.26 cm, the blobs 0.42 -> 0.40,
#: closer on 76 and 68; docs/method-notes.md section 24).
CONTACT_REPEATS = 4

#: The spread of the touches' gaps (interquartile range over median, ``ObservationPolicy.cover_even``) up to which the
#: default takes one gap for the cover's offset (the outer mean and the camera's inside points continued down to it).
#: Chosen in the loop on objects 100-109 (0.15 and 0.25; wide covers: the primitives 0.33 -> 0.26 cm, the blobs 0.90
#: -> 0.70) and judged on objects 0-99 under tight covers (none of 197 runs changed), 0-19 under wide ones (the
#: primitives 0.45 -> 0.32 cm, closer on 13 of 20; the blobs 0.70 -> 0.78, closer on 6 and worse on 8; both closer
#: at a quarter of the travel on 28 of 40), uneven ones (5 closer, 5 worse) and the real-cloth checks (the robot
#: study's sleeve unchanged, its poncho closer at the end on 7 of 10 seeds; MuJoCo's wide cloth closer on 4 of the
#: 5 runs it changed) (docs/method-notes.md section 27).
COVER_EVEN = 0.25

#: Times the default tries a contradicted inside point again at half its depth (``ObservationPolicy.inside_halvings``:
#: 2 cm, then 1 cm and 5 mm), on thin parts. Chosen in the loop on objects 100-119 under tight covers (blobs 0.41 ->
#: 0.37 cm, closer on 14 of 18; primitives 0.23 -> 0.22, closer on 10 and worse on 5) and judged on objects 0-99
#: (docs/method-notes.md section 25).
INSIDE_HALVINGS = 2

#: The named presets.
PRESETS = {"default": EstimatorSettings.default, "paper": EstimatorSettings.paper,
           "paper-2d": EstimatorSettings.paper_2d, "gap": EstimatorSettings.gap,
           "gapfield": EstimatorSettings.gap_field}


def _past_gap(p) -> str:
    """What the camera's inside points do past the cover gap ``p.vision_inside_gap``, in
    :meth:`EstimatorSettings.summary`'s words."""
    gap = f"a {_cm(p.vision_inside_gap)} cover gap"
    if p.cover_offset and p.vision_inside_deep:
        where = " a place at a time" if p.cover_gap_field else ""
        uneven = ("once they stop agreeing a place at a time, if they agreed first; else retracted"
                  if p.cover_uneven_field else "else retracted")
        even = (f" while the touches' gaps agree (interquartile range at most {p.cover_even:g} of the median; "
                f"{uneven})" if p.cover_even is not None and not p.cover_gap_field else "")
        carry = " through the learned transfer" if p.cover_carry else ""
        return f"past {gap}: continued down to the gap{where}, the outer mean standing for it{carry}{even}"
    return f"retracted past {gap}" + (", the outer mean then standing for it" if p.cover_offset else "")
