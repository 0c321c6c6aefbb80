"""Loose changes to the estimator's settings, from every door, turned into settings by one resolver.

A command-line flag (``--noise 0.05``, ``--voxel 0.03``, ``--estimator labels.ray_smoothing=none``), a scene file's
``[estimator]`` section, a study's runs and the keywords of :func:`torch_gpioius.explore` each change some of the
estimator's settings (:class:`~torch_gpioius.models.estimator.EstimatorSettings`) on top of what a world or a preset
holds. :class:`EstimatorOverrides` holds such changes, each checked once, when given, by the one check its setting
has everywhere:

* ``noise``: sigma^2 in :data:`~torch_gpioius.core.validation.NOISE_RANGE`
  (:func:`~torch_gpioius.core.validation.as_noise`);
* ``kernel``: a :class:`~torch_gpioius.kernels.KernelChoice` (a registered name and a length in
  :data:`~torch_gpioius.core.validation.KERNEL_LENGTH`) or a kernel object;
* ``voxel``: the camera's voxel edge, :func:`~torch_gpioius.models.labels.check_voxel` (0: every point);
* ``learn``: :data:`~torch_gpioius.models.estimator.LEARN`; ``restart_every``: steps between K_t's restarts, or None;
* ``labels``: single fields of the labelling policy, each by
  :meth:`~torch_gpioius.models.labels.ObservationPolicy.check_field`; ``policy``: a whole policy in its place.

:meth:`EstimatorOverrides.apply` makes settings from a base; the checks between settings (a kernel without a length
cannot learn one, a gap field needs the offset mean) are the settings' own, made there. A change names what it
changes (:meth:`EstimatorOverrides.to_dict`, what a study's folder and run records keep) and reads back
(:meth:`EstimatorOverrides.from_dict`, what a scene file's section and the command line's ``--estimator KEY=VALUE``
give).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

from ..core.validation import as_int, as_noise
from ..kernels import ExactKernel, KernelChoice, from_description
from .estimator import EstimatorSettings, as_learn
from .labels import ObservationPolicy, check_voxel

__all__ = ["EstimatorOverrides", "parse_assignment", "resolved", "warn_loose", "loose_keywords", "resolved_changes",
           "OVERRIDE_KEYS"]

#: The keys :meth:`EstimatorOverrides.from_dict` reads (``labels.<field>`` for one label; ``theta`` is
#: ``lengthscale`` under the paper's name).
OVERRIDE_KEYS = ("kernel", "lengthscale", "noise", "voxel", "learn", "restart_every", "labels")

#: ``restart_every`` left as the base holds it (None means: never restart).
KEEP = "keep"


@dataclass(frozen=True)
class EstimatorOverrides:
    """Changes to an estimator's settings, each checked when given (see the module docstring); empty: none.

    Attributes:
        kernel: a :class:`~torch_gpioius.kernels.KernelChoice` (a name and, or, a length: a length given replaces
            the base's length rule, a name alone keeps it) or an :class:`~torch_gpioius.kernels.ExactKernel` (it
            carries its own length; the rule is dropped); None: the base's.
        noise: sigma^2; None: the base's.
        voxel: the camera's voxel edge [m] (0: every point; the voxel rule is dropped); None: the base's.
        learn: "task", "length" or "all"; None: the base's.
        restart_every: steps between K_t's restarts, or None (never); ``"keep"``: the base's.
        labels: single fields of the labelling policy, as ``((field, value), ...)`` sorted by field (a dict is
            taken and sorted); applied on top of ``policy`` or the base's.
        policy: an :class:`~torch_gpioius.models.labels.ObservationPolicy` in place of the base's (the voxel rule
            dropped: the policy carries its voxel); None: the base's.

    Raises:
        ValueError: a value outside its setting's range, an unknown label field, or a voxel given twice (each named).
    """

    kernel: KernelChoice | ExactKernel | None = None
    noise: float | None = None
    voxel: float | None = None
    learn: str | None = None
    restart_every: int | str | None = KEEP
    labels: tuple = ()
    policy: ObservationPolicy | None = None

    def __post_init__(self) -> None:
        kernel = self.kernel
        if isinstance(kernel, str):
            kernel = KernelChoice(kernel)
        if isinstance(kernel, KernelChoice) and not kernel:
            kernel = None
        if kernel is not None and not isinstance(kernel, (KernelChoice, ExactKernel)):
            raise ValueError(f"kernel: expected a KernelChoice, a kernel's name or an ExactKernel, got "
                             f"{type(kernel).__name__}")
        object.__setattr__(self, "kernel", kernel)
        if self.noise is not None:
            object.__setattr__(self, "noise", as_noise(self.noise))
        labels = dict(self.labels)
        if "voxel" in labels:                       # one voxel: the one that drops the voxel rule
            if self.voxel is not None:
                raise ValueError("voxel, labels.voxel: the camera's voxel given twice; give voxel")
            voxel = labels.pop("voxel")
            object.__setattr__(self, "voxel", 0.0 if voxel is None else voxel)
        if self.voxel is not None:
            object.__setattr__(self, "voxel", check_voxel(self.voxel))
        if self.learn is not None:
            as_learn(self.learn)
        if not (isinstance(self.restart_every, str) and self.restart_every == KEEP):
            object.__setattr__(self, "restart_every", as_int(self.restart_every, "restart_every", 1, 1_000_000,
                                                             allow_none=True))
        object.__setattr__(self, "labels", tuple(sorted(
            (name, ObservationPolicy.check_field(name, _label_value(name, value))) for name, value in labels.items())))
        if self.policy is not None and not isinstance(self.policy, ObservationPolicy):
            raise ValueError(f"policy: expected an ObservationPolicy, got {type(self.policy).__name__}")

    def __bool__(self) -> bool:
        return bool(self.kernel is not None or self.noise is not None or self.voxel is not None or self.learn
                    or self.restart_every != KEEP or self.labels or self.policy is not None)

    def apply(self, base: EstimatorSettings) -> EstimatorSettings:
        """``base`` with these changes (``base`` itself when there are none).

        Raises:
            ValueError: settings that do not hold together (the settings' own checks: a kernel without a length and
                ``learn`` other than "task", a gap field without the offset mean, ...), naming them.
        """
        if not isinstance(base, EstimatorSettings):
            raise ValueError(f"settings: expected EstimatorSettings, got {type(base).__name__}")
        if not self:
            return base
        est = base
        if self.policy is not None:
            est = est.replace(labels=self.policy, voxel_rule=None)
        if self.labels:
            est = est.replace(labels=dataclasses.replace(est.labels, **dict(self.labels)))
        if self.voxel is not None:
            est = est.with_voxel(self.voxel)
        chosen = self.kernel.apply(est.kernel) if isinstance(self.kernel, KernelChoice) else None
        if chosen is not None and not chosen.learnable_length:
            est = est.replace(kernel=chosen)        # a kind without a length: no rule to keep
        elif chosen is not None:
            length = est.lengthscale
            est = est.with_kernel(self.kernel)
            if est.length_rule is not None and length is not None and est.lengthscale != length:
                # a name alone keeps the rule: the new kind at the length the rule gave the base (a base not yet
                # sized to its object is sized later, by the same rule)
                est = est.replace(kernel=KernelChoice(lengthscale=length).apply(est.kernel),
                                  length_rule=est.length_rule)
        elif self.kernel is not None:
            est = est.replace(kernel=self.kernel)   # a kernel object carries its length: the rule is dropped
        changes = {}
        if self.noise is not None:
            changes["noise"] = self.noise
        if self.learn is not None:
            changes["learn"] = self.learn
        if self.restart_every != KEEP:
            changes["restart_every"] = self.restart_every
        return est.replace(**changes) if changes else est

    def merged(self, later: "EstimatorOverrides") -> "EstimatorOverrides":
        """These changes with ``later``'s on top (``later`` wins where both set one setting; labels merge)."""
        if not isinstance(later, EstimatorOverrides):
            raise ValueError(f"overrides: expected EstimatorOverrides, got {type(later).__name__}")
        changes = {f.name: getattr(later, f.name) for f in dataclasses.fields(later)
                   if f.name != "labels" and getattr(later, f.name) != getattr(EstimatorOverrides(), f.name)}
        return dataclasses.replace(self, labels={**dict(self.labels), **dict(later.labels)}, **changes)

    # ------------------------------------------------------------------ as plain data
    def to_dict(self) -> dict:
        """The changes as plain, JSON-able data, only those made (what a study's folder and its run records keep;
        :meth:`from_dict` reads it back)."""
        out: dict = {}
        if isinstance(self.kernel, KernelChoice):
            out.update({k: v for k, v in (("kernel", self.kernel.name), ("lengthscale", self.kernel.lengthscale))
                        if v is not None})
        elif self.kernel is not None:
            out["kernel"] = self.kernel.describe()
        for key in ("noise", "voxel", "learn"):
            if getattr(self, key) is not None:
                out[key] = getattr(self, key)
        if self.restart_every != KEEP:
            out["restart_every"] = self.restart_every
        labels = {} if self.policy is None else dataclasses.asdict(self.policy)
        labels.update(dict(self.labels))
        if labels:
            out["labels"] = {k: list(v) if isinstance(v, tuple) else v for k, v in labels.items()}
        if self.policy is not None:
            out["policy"] = True                    # the labels are a whole policy, not single changes
        return out

    @classmethod
    def from_dict(cls, data: dict, where: str = "estimator") -> "EstimatorOverrides":
        """Changes from plain data: :meth:`to_dict`'s, a scene file's ``[estimator]`` section, or the command line's
        ``--estimator KEY=VALUE`` pairs. Keys: :data:`OVERRIDE_KEYS` (``theta`` for ``lengthscale``), ``labels`` a
        table of the policy's fields, or ``labels.<field>`` for one; a kernel a registered name or a description;
        the text "none" is None (TOML has no null).

        Raises:
            ValueError: ``where``: an unknown key (naming the keys), or a value outside its range.
        """
        if not isinstance(data, dict):
            raise ValueError(f"{where}: expected a table of settings, got {type(data).__name__}")
        data = {k: _none(v) for k, v in data.items()}
        labels = data.pop("labels", None) or {}
        if not isinstance(labels, dict):
            raise ValueError(f"{where}: labels: expected a table of the labels' fields, got {labels!r}")
        labels = {k: _none(v) for k, v in labels.items()}
        for key in [k for k in data if isinstance(k, str) and k.startswith("labels.")]:
            labels[key.removeprefix("labels.")] = data.pop(key)
        whole = bool(data.pop("policy", False))
        if "theta" in data:
            if "lengthscale" in data:
                raise ValueError(f"{where}: lengthscale, theta: the same length under two names; give lengthscale")
            data["lengthscale"] = data.pop("theta")
        unknown = sorted(set(data) - set(OVERRIDE_KEYS))
        if unknown:
            fields = ", ".join(f.name for f in dataclasses.fields(ObservationPolicy))
            raise ValueError(f"{where}: unknown key(s) {unknown}; allowed {list(OVERRIDE_KEYS)} and labels.<field> "
                             f"for a field of the labels ({fields})")
        try:
            kernel = data.get("kernel")
            if isinstance(kernel, dict):
                kernel = from_description(kernel)
                if data.get("lengthscale") is not None:
                    kernel = KernelChoice(lengthscale=data["lengthscale"]).apply(kernel)
            elif kernel is None or isinstance(kernel, str):
                kernel = KernelChoice(kernel, data.get("lengthscale"))
            else:
                raise ValueError(f"kernel: expected a kernel's name, got {kernel!r}")
            policy = None
            if whole:
                policy = ObservationPolicy(**{k: _label_value(k, v) for k, v in labels.items()})
                labels = {}
            return cls(kernel=kernel, noise=data.get("noise"), voxel=data.get("voxel"), learn=data.get("learn"),
                       restart_every=data.get("restart_every", KEEP), labels=labels, policy=policy)
        except (TypeError, ValueError) as exc:
            raise ValueError(f"{where}: {exc}") from None

    @classmethod
    def from_assignments(cls, pairs, where: str = "--estimator") -> "EstimatorOverrides":
        """Changes from ``KEY=VALUE`` texts (the command line's ``--estimator``, each parsed by
        :func:`parse_assignment`).

        Raises:
            ValueError: a text that is not ``KEY=VALUE``, a key given twice, or :meth:`from_dict`'s errors.
        """
        data: dict = {}
        for text in pairs or ():
            key, value = parse_assignment(text, where)
            if key in data:
                raise ValueError(f"{where}: {key} given twice")
            data[key] = value
        return cls.from_dict(data, where)


def resolved(estimator, base: EstimatorSettings) -> EstimatorSettings:
    """Settings from what a caller gives in place of ``base``: an :class:`EstimatorSettings` (itself), an
    :class:`EstimatorOverrides` or its plain dict (a scene file's ``[estimator]`` section), applied to ``base``.

    Raises:
        ValueError: anything else, or changes that do not hold together (named).
    """
    if isinstance(estimator, dict):
        estimator = EstimatorOverrides.from_dict(estimator)
    if isinstance(estimator, EstimatorOverrides):
        estimator = estimator.apply(base)
    if not isinstance(estimator, EstimatorSettings):
        raise ValueError(f"estimator: expected EstimatorSettings or EstimatorOverrides, got {type(estimator).__name__}")
    return estimator


def resolved_changes(changes) -> "EstimatorOverrides":
    """Changes in any of their forms as one :class:`EstimatorOverrides`: one itself, its plain dict (a scene file's
    ``[estimator]`` section), ``KEY=VALUE`` texts (the command line's ``--estimator``) or None (none).

    Raises:
        ValueError: anything else, or a bad key or value (named).
    """
    if changes is None:
        return EstimatorOverrides()
    if isinstance(changes, dict):
        return EstimatorOverrides.from_dict(changes)
    if isinstance(changes, (list, tuple)):
        return EstimatorOverrides.from_assignments(changes)
    if not isinstance(changes, EstimatorOverrides):
        raise ValueError(f"estimator: expected EstimatorOverrides, its dict or KEY=VALUE texts, got "
                         f"{type(changes).__name__}")
    return changes


def warn_loose(owner: str, stacklevel: int, **given) -> list[str]:
    """The DeprecationWarning of an entry point's loose estimator keywords (``given``, None or "default": not given,
    as :func:`loose_keywords` fills them; they still work, through the same resolver, for one release): the
    estimator's settings are one object, ``settings=EstimatorOverrides(...)``. ``stacklevel`` counts from the caller
    of this function, as :func:`warnings.warn`'s. Returns the names given.
    """
    named = [k for k, v in given.items() if v is not None and not (isinstance(v, str) and v == "default")]
    if named:
        import warnings

        warnings.warn(f"{owner}({', '.join(f'{k}=' for k in named)}): give settings=EstimatorOverrides("
                      f"{', '.join(f'{k}=...' for k in named)}) (torch_gpioius.models.overrides; the estimator's "
                      "settings in one object, docs/reference/settings.md); these keywords go in a later release",
                      DeprecationWarning, stacklevel=stacklevel + 1)
    return named


def loose_keywords(owner: str, given: dict, allowed: tuple[str, ...]) -> dict:
    """The deprecated loose estimator keywords an entry point still reads for one release from its ``**deprecated``
    (``given``), by name, each defaulting to None (``restart_every``: "default", the world's); they are out of its
    signature, so that one object, ``settings=``, is what the signature offers.

    Raises:
        TypeError: a keyword the entry point never took, as Python names an unexpected one.
    """
    unknown = sorted(set(given) - set(allowed))
    if unknown:
        raise TypeError(f"{owner}() got an unexpected keyword argument {unknown[0]!r}")
    out = {name: None for name in allowed}
    if "restart_every" in allowed:
        out["restart_every"] = "default"
    out.update(given)
    return out


def _none(value):
    """None for the text "none" (TOML has no null: a scene file writes ``ray_smoothing = "none"``), else ``value``."""
    return None if isinstance(value, str) and value.strip().lower() in ("none", "null") else value


def _label_value(name: str, value):
    """A label's value as the policy holds it: a camera bound may be written as two numbers, ``"0.012,0.035"`` or a
    list (metres, radians; the command line's ``--camera-bound`` takes "12mm,2deg")."""
    if name == "camera_bound" and isinstance(value, str):
        try:
            return tuple(float(v) for v in value.split(","))
        except ValueError:
            return value                              # refused by the policy's check, naming the field
    if name == "camera_bound" and isinstance(value, list):
        return tuple(value)
    return value


def parse_assignment(text: str, where: str = "--estimator") -> tuple[str, object]:
    """``(key, value)`` of a ``KEY=VALUE`` text: the value ``none`` / ``null`` is None, ``true`` / ``false`` (or
    ``on`` / ``off``) a bool, a number a number, anything else the text itself (a kernel's name, a camera bound
    "12mm,2deg").

    Raises:
        ValueError: a text without ``=`` or without a key, naming ``where``.
    """
    if not isinstance(text, str) or "=" not in text or not text.partition("=")[0].strip():
        raise ValueError(f"{where}: expected KEY=VALUE (e.g. noise=0.05, labels.ray_smoothing=none), got {text!r}")
    key, _, value = (part.strip() for part in text.partition("="))
    lowered = value.lower()
    if lowered in ("none", "null"):
        return key, None
    if lowered in ("true", "on", "false", "off"):
        return key, lowered in ("true", "on")
    for kind in (int, float):
        try:
            return key, kind(value)
        except ValueError:
            pass
    return key, value
