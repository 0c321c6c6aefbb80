"""The settings every 3-D world borrows, sized to a body: the robot study's (the paper's, Sec. VI-A) and this
library's for a user's object (:func:`object_defaults`), the experimental gap settings, the simulated camera's views,
and the inside points' and estimator's loose settings as one change (:func:`estimator_changes`).

The estimator's own presets (kernel, sigma^2, labels, rules) are :class:`~torch_gpioius.models.estimator.
EstimatorSettings`'; these wrap them with a world's exploration settings (step, stop rules, views). The force-field
and MuJoCo worlds both build their settings here (:func:`settings_for`).
"""

from __future__ import annotations

import numpy as np
import trimesh

from ..exploration.stopping import TravelBudget
from ..exploration.world import ExplorationDefaults
from ..models.estimator import (COVER_GAP_LIMIT, GAP_FIELD_LABELS, GAP_LABELS, INSIDE_DEPTH,  # noqa: F401
                                EstimatorSettings)
from ..models.labels import ObservationPolicy
from ..models.overrides import EstimatorOverrides, resolved_changes

__all__ = ["ROBOT_STUDY_DEFAULTS", "VIEWS", "DEFAULT_VIEWS", "SETTINGS", "object_defaults", "gap_defaults",
           "gap_field_defaults", "settings_for", "INSIDE_SETTINGS", "inside_labels", "ESTIMATOR_KEYS",
           "estimator_changes", "with_inside_depths", "as_views"]

#: The robot study's settings (Sec. VI-A): theta 0.15, sigma^2 0.08, alpha 1 cm, 1.5 m of travel, the range
#: penalty of eq. (25), the camera averaged in 5 cm voxels and cropped to 15 cm around the range.
ROBOT_STUDY_DEFAULTS = ExplorationDefaults(step=0.01, max_steps=400, stop=(TravelBudget(1.5),), metrics_every=1,
                                           approach_travel=2.0, estimator=EstimatorSettings.paper())


#: The simulated views of a force-field scene (:meth:`Scene3D.cameras`).
VIEWS = ("fixed", "mirrored", "wrist")
#: The views a scene has unless told otherwise.
DEFAULT_VIEWS = ("fixed",)


#: What ``Scene3D.from_mesh(settings=...)`` accepts: "default" (this library's, for a user's object), "paper",
#: "gap" (an experiment: the defaults with one gap whatever the touches' spread, :func:`gap_defaults`) or
#: "gapfield" (another: that gap a place at a time, :func:`gap_field_defaults`).
SETTINGS = ("default", "paper", "gap", "gapfield")


def object_defaults(mesh: trimesh.Trimesh, base: ExplorationDefaults | None = None) -> ExplorationDefaults:
    """The exploration settings for a user's object (``Scene3D.from_mesh(settings="default")``): the robot study's
    (:data:`ROBOT_STUDY_DEFAULTS`, or ``base``: the MuJoCo world's own) with four changes, each measured on shapes
    nobody tuned to (docs/results-real.md):

    - the camera's voxels a tenth of the body's largest extent, 2-5 cm (the paper's 5 cm voxels were sized for a
      torso, and leave a 15 cm body a handful of outer points);
    - a second free-space point 10 cm in front of each seen point (``ObservationPolicy.vision_free_far``);
    - a Matérn-5/2 kernel in place of the inverse multiquadric: with the denser camera data the inverse
      multiquadric's heavy tails (``k ~ 1/r``) swing the mean below zero 5-10 cm away from all data, a phantom
      surface that a light-tailed kernel does not make; its length a fifth of the body's largest extent, 4-10 cm
      (:class:`~torch_gpioius.models.estimator.LengthRule`; a fixed 10 cm rounded off a 20 cm body's ears and
      corners, docs/results-benchmark.md "The kernel's length");
    - points known to lie inside: 2 cm behind each contact along the measured force and 2 cm behind each seen point
      along the cloud's normal, labelled -0.4 (``ObservationPolicy.touch_inside``, ``vision_inside``; the free-space
      ramp continued inside). With the paper's labels alone the estimate lay 0.6-0.9 cm inside the body on tight
      covers; the inside points bring it within 4 mm (docs/method-notes.md section 13). They assume a body thicker
      than 2 cm: on a thin-walled one (the mug) they overshoot instead; one that the far side of a thinner part
      contradicts is tried again at 1 cm and 5 mm (``ObservationPolicy.inside_halvings``, section 25).
      They also assume a cover within 2 cm of the
      body: the camera's are retracted once the touches show it standing more than 3 cm off
      (``ObservationPolicy.vision_inside_gap``, :data:`COVER_GAP_LIMIT`), unless the touches' gaps agree (their
      interquartile range at most a quarter of their median, ``ObservationPolicy.cover_even``): then the outer
      task's prior mean stands for the gap they measure (``cover_offset``) and the camera's inside points are
      continued down to it (``vision_inside_deep``), for as long as they agree. One gap whatever the touches'
      spread harmed the robot study's loose sleeve and poncho (docs/method-notes.md sections 15 and 26); read only
      while they agree it leaves the sleeve as it was and helps under covers that stand off evenly (section 27).
    """
    d = ROBOT_STUDY_DEFAULTS if base is None else base
    return d.with_estimator(EstimatorSettings.default().for_extent(float(np.max(mesh.extents))))


def gap_defaults(mesh: trimesh.Trimesh, base: ExplorationDefaults | None = None) -> ExplorationDefaults:
    """:func:`object_defaults` with the one gap taken whether the touches agree on it or not (``settings="gap"``, an
    experiment, for a cover known to stand off evenly): once the touches show the cover standing more than 3 cm off,
    the outer task's prior mean stands for the gap they measure (``ObservationPolicy.cover_offset``) and the camera's
    inside points are kept and continued down to it, each labelled by its depth (``ObservationPolicy.
    vision_inside_deep``), for the rest of the run (the default only while the touches' gaps agree,
    ``cover_even``). Measured offline on finished runs' data in docs/method-notes.md section 16, and in the loop in
    docs/results-benchmark.md ("A transfer that knows the gap, in the loop")."""
    return object_defaults(mesh, base).estimator_changed(labels=GAP_LABELS)


def gap_field_defaults(mesh: trimesh.Trimesh, base: ExplorationDefaults | None = None) -> ExplorationDefaults:
    """:func:`gap_defaults` with the gap a place at a time (``settings="gapfield"``, an experiment): the outer task's
    prior mean from a smooth field of the contacts' gaps, set once it exceeds 3 cm somewhere, and the camera's inside
    points continued down to the field's gap where each lies (``ObservationPolicy.cover_gap_field``; for covers whose
    gap varies over the body, docs/method-notes.md section 18)."""
    return object_defaults(mesh, base).estimator_changed(labels=GAP_FIELD_LABELS)


def settings_for(settings: str, mesh: trimesh.Trimesh, paper: ExplorationDefaults | None = None) -> dict:
    """``{"defaults", "views"}`` of a world under ``settings`` for a body ``mesh``: "default" (:func:`object_defaults`
    on the world's own ``paper`` settings, all three :data:`VIEWS`), "gap" (:func:`gap_defaults`, likewise),
    "gapfield" (:func:`gap_field_defaults`, likewise) or
    "paper" (``paper``, default :data:`ROBOT_STUDY_DEFAULTS`, and the fixed camera alone). Both 3-D worlds build
    their settings here.

    Raises:
        ValueError: an unknown setting.
    """
    if settings not in SETTINGS:
        raise ValueError(f"settings: must be one of {SETTINGS}, got {settings!r}")
    paper = ROBOT_STUDY_DEFAULTS if paper is None else paper
    if settings == "paper":
        return {"defaults": paper, "views": "paper"}
    if settings in ("gap", "gapfield"):
        make = gap_defaults if settings == "gap" else gap_field_defaults
        return {"defaults": make(mesh, base=paper), "views": VIEWS}
    return {"defaults": object_defaults(mesh, base=paper), "views": VIEWS}


#: The inside points' settings (:func:`with_inside_depths`; ``ObservationPolicy``'s fields of these names).
INSIDE_SETTINGS = ("touch_inside", "vision_inside", "vision_inside_gap", "cover_offset")


def inside_labels(**depths) -> dict:
    """The labels' fields of :data:`INSIDE_SETTINGS` given (None: not given), each checked by the labels' own range
    (:meth:`~torch_gpioius.models.labels.ObservationPolicy.check_field`), where a depth or gap of 0 means none (the
    scene files' and ``from_mesh``'s convention).

    Raises:
        ValueError: a value outside its range, or an unknown name (names it).
    """
    given = {k: v for k, v in depths.items() if v is not None}
    unknown = set(given) - set(INSIDE_SETTINGS)
    if unknown:
        raise ValueError(f"inside depths: unknown {sorted(unknown)}; the settings are {', '.join(INSIDE_SETTINGS)}")
    return {k: ObservationPolicy.check_field(k, None if k != "cover_offset" and v == 0 else v)
            for k, v in given.items()}


#: The estimator's settings a force-field scene took as loose values before the one object (``Scene3D.from_mesh``'s
#: deprecated keywords, a scene file's ``[forcefield]`` section): :func:`estimator_changes` makes them one.
ESTIMATOR_KEYS = ("kernel", "noise", "voxel", "learn") + INSIDE_SETTINGS


def estimator_changes(estimator=None, **loose) -> "EstimatorOverrides":
    """One :class:`~torch_gpioius.models.overrides.EstimatorOverrides` from ``estimator`` (any form
    :func:`~torch_gpioius.models.overrides.resolved_changes` reads, or None) with the loose values of
    :data:`ESTIMATOR_KEYS` on top (None: not given): ``kernel``, ``noise``, ``voxel`` and ``learn`` as the overrides
    take them, the inside points' depths and gap as labels where 0 means none (:func:`inside_labels`).

    Raises:
        ValueError: an unknown key, or a value outside its range (names it).
    """
    unknown = sorted(set(loose) - set(ESTIMATOR_KEYS))
    if unknown:
        raise ValueError(f"estimator: unknown {unknown}; the loose settings are {', '.join(ESTIMATOR_KEYS)}")
    estimator = resolved_changes(estimator)
    labels = inside_labels(**{k: loose.get(k) for k in INSIDE_SETTINGS})
    return estimator.merged(EstimatorOverrides(kernel=loose.get("kernel"), noise=loose.get("noise"),
                                               voxel=loose.get("voxel"), learn=loose.get("learn"), labels=labels))


def with_inside_depths(defaults: ExplorationDefaults, **depths) -> ExplorationDefaults:
    """``defaults`` with the inside points' depths [m] given (``touch_inside``, ``vision_inside``; 0: none; None:
    as they are), the cover's gap beyond which the camera's are retracted (``vision_inside_gap``; 0: never), each
    checked to lie in [0, 0.1] m, and whether the outer task's prior mean then stands for that gap (``cover_offset``,
    True or False) (:func:`inside_labels`).

    Raises:
        ValueError: a value outside that range, or an unknown name (names it).
    """
    checked = inside_labels(**depths)
    return defaults.estimator_changed(labels=checked) if checked else defaults


def as_views(views) -> tuple[str, ...]:
    """The names of a scene's views from names, a count (1-3, in :data:`VIEWS` order) or "paper" (the fixed camera).

    Raises:
        ValueError: an unknown name, a repeated one, no views, or a count outside 1-3.
    """
    if isinstance(views, str):
        views = ("fixed",) if views == "paper" else (views,)
    if isinstance(views, (int, np.integer)) and not isinstance(views, bool):
        if not 1 <= int(views) <= len(VIEWS):
            raise ValueError(f"views: a count must be 1-{len(VIEWS)} ({', '.join(VIEWS)}), got {views}")
        return VIEWS[:int(views)]
    try:
        names = tuple(views)
    except TypeError:
        raise ValueError(f"views: expected names from {VIEWS}, a count or 'paper', got {views!r}") from None
    bad = [v for v in names if v not in VIEWS]
    if bad or not names or len(set(names)) != len(names):
        raise ValueError(f"views: expected distinct names from {VIEWS}, a count or 'paper', got {views!r}")
    return names
