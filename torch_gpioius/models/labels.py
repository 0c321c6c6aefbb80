"""The labelling policy of the estimator: which observations a touch and a capture become, and with which labels.

An estimator turns observations into a model with labels (0 on a surface, 1 in free space, negative inside); the
:class:`ObservationPolicy` says which points carry which label: the camera's free space in front of the seen surface
(one point, or two), the touch's free space along the path, points known to lie inside behind contacts and behind the
seen surface, the cover-gap retraction, and the voxels the camera's points are averaged in. It belongs to the model
layer (:class:`~torch_gpioius.models.estimator.EstimatorSettings` holds one), not to a world: a simulated run, a fit on
a user's files and a bag import label alike. :mod:`torch_gpioius.exploration.observations` applies it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields, replace

import numpy as np

from ..core.validation import INSIDE_DEPTH_MAX, as_int

__all__ = ["ObservationPolicy", "check_voxel", "MAX_VOXEL"]


@dataclass(frozen=True)
class ObservationPolicy:
    """Which observations the exploration records (see docs/method-notes.md for the evidence).

    Attributes:
        vision_free_offset: distance in front of each seen outer point (along the camera ray, or outward in the 2-D
            view) of the camera's free-space point (y = 1, task outer) [m]; ``None`` disables them.
        voxel: edge of the voxels the camera's points are averaged in [m] (paper: 0.05); ``None`` keeps them all.
        crop_margin: the cloud is cropped to the exploration range grown by this [m] (what a real camera sees
            beyond, tables and walls, is not the object); ``None`` keeps everything.
        free_space_spacing: spacing of the free-space samples along the path the fingertip occupied with
            ``|F|`` below the contact threshold (y = 1, task inner) [m].
        free_space_margin: free-space samples closer than this to any contact are not recorded, and recorded ones
            are retracted when a later contact lands closer [m]; keeps the inner Gram block well conditioned.
        vision_free_far: a second free-space point this far in front of each seen point [m] (beyond the paper, which
            has one): the camera's rays were free all the way, and a second point holds the field up in front of
            the object where one point 5 cm out leaves it free to swing below zero (a phantom surface); None: one.
        touch_inside: a point this far behind each contact along the measured contact normal (the force's direction)
            [m], labelled inside (:meth:`inside_label`; beyond the paper, docs/method-notes.md section 13); None: none.
        vision_inside: a point this far behind each seen point along the cloud's inward normal [m]
            (:meth:`~torch_gpioius.sensors.PointCloud.behind`, one per voxel), labelled inside; it assumes the object
            is thicker than this there; None: none.
        vision_inside_gap: the camera's inside points are retracted, all of them, once the touches show the cover
            standing off the body by more than this [m] (:func:`retract_vision_inside`: the median distance from
            the contacts to the seen cover, :func:`cover_gap`): behind a cover that
            far off, ``vision_inside`` deep lies in the gap, free space for the body, and the task correlation
            carries it onto the inner estimate as body. None: kept whatever the touches show.
        cover_offset: once the touches show the cover standing off the body by more than ``vision_inside_gap``, the
            outer task's prior mean is set to ``1 - gap / ramp`` (:func:`offset_outer_mean`), so that the transfer
            carries the cover's shape onto the body without its offset (the camera's inside points are retracted
            as without it; docs/method-notes.md section 15); on in the ``"default"`` preset, where ``cover_even``
            keeps it to covers whose gap the touches agree on; False (this class's default, the paper's): one mean
            for both tasks.
        vision_inside_deep: with ``cover_offset``, once the touches show the cover standing off by a gap ``g`` beyond
            ``vision_inside_gap``, the camera's inside points are kept (not retracted) and more are added behind
            them every ``vision_inside`` down to ``g + vision_inside``, each labelled by its depth
            (:func:`~torch_gpioius.exploration.observations.deepen_vision_inside`): the outer field a signed distance
            down to the level the offset mean reads (docs/method-notes.md section 16); on in the ``"default"``
            preset. False (this class's default): as without it.
        cover_gap_field: with ``cover_offset`` and ``vision_inside_deep``, the gap a place at a time: the outer
            task's prior mean ``1 - g(x) / ramp`` from a smooth field ``g`` regressed from each contact's gap
            (:class:`~torch_gpioius.models.gapfield.GapField`, :func:`~torch_gpioius.exploration.observations.
            offset_outer_mean`), set once the field somewhere exceeds ``vision_inside_gap`` and renewed as it moves,
            and the camera's inside points continued down to the field's gap where each lies, placed again each
            time (docs/method-notes.md section 18). False (the default): one gap, the touches' median.
        cover_even: with ``cover_offset`` and ``vision_inside_deep`` (one gap), the gap counts as the cover's offset
            only while the contacts' gaps agree: their interquartile range at most this share of their median
            (:func:`~torch_gpioius.exploration.observations.gap_spread`). Where they spread wider, the cover does not
            stand off evenly and one number is wrong over most of it: the camera's inside points are retracted as
            without the gap settings, and an outer mean already set goes back to the paper's one mean, for the rest
            of the run (docs/method-notes.md section 27). The ``"default"`` preset's is 0.25 (``COVER_EVEN``). None
            (this class's default): the one gap whatever its spread. Without the one gap's settings (or with
            ``cover_gap_field``, whose field follows a gap that varies) it does nothing.
        cover_uneven_field: with ``cover_even``, a cover whose one gap was taken (the touches agreed on it) and whose
            touches then stop agreeing (their spread past ``cover_even``) takes the gap a place at a time
            (``cover_gap_field``'s field, :class:`~torch_gpioius.models.gapfield.GapField`) in place of the paper's
            one mean, where that field exceeds ``vision_inside_gap`` at a region of their places
            (:data:`~torch_gpioius.exploration.observations.FIELD_SHARE`; judged once they measured
            :data:`~torch_gpioius.exploration.observations.FIELD_PLACES` places, the one gap kept until then): the
            camera's inside points are kept and continued down to the field's gap where each lies, and the field is
            the outer mean for the rest of the run, renewed as it moves. Where the field stays below, and where the
            touches disagree from their first judgement (a tight cover bridging a concavity, a sagging sleeve:
            there a field made runs worse), as ``cover_even`` alone (docs/method-notes.md section 32). On in the
            ``"default"`` preset; False (this class's default): the one gap given up once the touches stop agreeing.
            Without ``cover_even`` and the one gap's settings (no gap is ever given up), or with ``cover_gap_field``
            (whose field is taken whatever the spread), it does nothing.
        cover_carry: with ``cover_offset``, the outer mean that stands for the gap ``g`` (one number, or a field
            ``g(x)`` with ``cover_gap_field`` or ``cover_uneven_field``, raised alike) also answers the transfer K_t
            learned: away from the touches the inner estimate is ``1 + r (mu_out - m_out)``
            with ``r = K_t[0,1] / K_t[1,1]``, which puts its zero level ``g`` below the cover only when ``r = 1``;
            with ``r`` below 1 (0.5-0.95 under 4 cm covers) the estimate sinks into the body away from the touches.
            The mean renewed once set is ``1 - g / ramp + (1 / r - 1)``
            (:func:`~torch_gpioius.exploration.observations.carried_mean`, ``r`` the last fit's, floored at
            :data:`~torch_gpioius.exploration.observations.CARRY_MIN_RATIO`), moved when it moves by more than
            :data:`~torch_gpioius.exploration.observations.OFFSET_STEP` of gap; set first without it (K_t learned at
            the mean of 1 has an ``r`` that carries the gap itself). A fit on files applies it once after the first
            fit and re-learns K_t (docs/method-notes.md section 31). On in the ``"default"`` preset; False (this
            class's default): ``1 - g / ramp``.
        camera_bound: ``(translation [m], rotation [rad])``, the largest error the camera's calibration may have:
            once the contacts are many enough, and again as more come, each view's capture is moved rigidly about its
            camera to agree with them and with the other views, within that bound, and the camera's observations are
            labelled again from the corrected captures
            (:func:`~torch_gpioius.exploration.calibration.correct_camera`); None (the default): the captures as the
            calibration places them.
        camera_table: with ``camera_bound``, each capture's view of the table the object stands on (the points a
            camera keeps apart as ``PointCloud.support``) is held to the table's plane as well, at the height the
            contact controller keeps the fingertip above (``ContactConfig.floor``, which the robot knows); where the
            captures carry no table points or there is no floor, as without it. True (the default with a bound):
            the plane fixes the rotations about horizontal axes and the height, which the contacts on a body's few
            faces leave loose (docs/method-notes.md section 17).
        ray_smoothing: each seen point is averaged in the voxel where its depth, smoothed along the camera's rays over
            this many neighbouring rays of the same view, lies
            (:meth:`~torch_gpioius.sensors.PointCloud.smoothed_along_rays`); the voxel's mean is of the measured
            points. Depth noise then no longer carries points into the voxels behind the surface, whose means lay
            inside it and contradicted the inside points (docs/method-notes.md section 20). Without voxels, the
            smoothed points themselves. The free space and the inside points are the measured cloud's. None: each
            point in the voxel it was measured in (the paper).
        contact_repeats: each contact (a point touch's or a tap's y = 0 observation, in an exploration, a contacts
            file or a bag; the inside and free-space points it brings, and a tactile pad's patch points, are not
            repeated) enters the model this many times: exactly one observation with the noise ``sigma^2 / k``,
            the camera's observations keeping ``sigma^2`` (k identical labels with independent noise are, for the
            posterior and for K_t's optimum, one label with a k-th of the variance; the marginal likelihood differs
            by a constant). A fingertip's settled contact is measured more precisely than a voxel mean of a depth
            camera's cloud; one sigma^2 for both counts them alike. 1 (the default): the paper's one noise
            (docs/method-notes.md section 24).
        inside_halvings: where an inside point (the camera's, ``vision_inside`` behind a seen voxel, or a touch's,
            ``touch_inside`` behind a contact) is contradicted (a part thinner than its depth: a seen or felt
            surface within :data:`~torch_gpioius.exploration.observations.INSIDE_CLEARANCE` of its depth, or free
            space within it), it is tried again on the same line at half the depth (labelled by that depth), up to
            this many times; the first that nothing contradicts is kept (the camera's only where a seen surface
            facing the other way is what contradicts it, not a stray voxel in front of its own face). Without it a
            thin part (a limb, a lid's rim)
            keeps no inside point at all, and the estimate erodes it (docs/method-notes.md section 25). 0 (the
            default): dropped.
    """

    vision_free_offset: float | None = 0.05
    voxel: float | None = None
    crop_margin: float | None = None
    free_space_spacing: float = 0.02
    free_space_margin: float = 0.02
    vision_free_far: float | None = None
    touch_inside: float | None = None
    vision_inside: float | None = None
    vision_inside_gap: float | None = None
    cover_offset: bool = False
    vision_inside_deep: bool = False
    cover_gap_field: bool = False
    cover_even: float | None = None
    camera_bound: tuple | None = None
    camera_table: bool = True
    ray_smoothing: int | None = None
    contact_repeats: int = 1
    inside_halvings: int = 0
    cover_carry: bool = False
    cover_uneven_field: bool = False

    def __post_init__(self) -> None:
        for f in fields(self):
            object.__setattr__(self, f.name, self.check_field(f.name, getattr(self, f.name)))
        if self.cover_gap_field and not (self.cover_offset and self.vision_inside_deep):
            raise ValueError("ObservationPolicy.cover_gap_field: needs cover_offset and vision_inside_deep (the gap "
                             "field stands in for their one gap)")
        if self.vision_free_far is not None and (self.vision_free_offset is None or
                                                 not self.vision_free_far > self.vision_free_offset):
            raise ValueError(f"ObservationPolicy.vision_free_far: must lie beyond vision_free_offset "
                             f"({self.vision_free_offset!r} m), got {self.vision_free_far!r}")

    @classmethod
    def check_field(cls, name: str, value):
        """``value`` as the field ``name`` holds it, checked against that field's one range (every door that sets a
        label's field, a keyword, a command-line flag, a scene file, checks it here); the checks between fields
        are the constructor's.

        Raises:
            ValueError: an unknown field (names the fields), or a value outside its range (names the field, the
                value and the range, :meth:`field_range`).
        """
        where = f"ObservationPolicy.{name}"
        if name == "ray_smoothing":
            return as_int(value, f"{where} (rays)", *_RAYS, allow_none=True)
        if name == "contact_repeats":
            return as_int(value, where, *_REPEATS)
        if name == "inside_halvings":
            return as_int(value, where, *_HALVINGS)
        if name == "camera_bound":
            ok = value is None or (isinstance(value, (tuple, list)) and len(value) == 2
                                   and all(_in_range(v, hi) for v, hi in zip(value, _CAMERA_BOUND)))
        elif name in _FLAGS:
            ok = isinstance(value, bool)
        elif name in _LENGTHS:
            ok = value is None or _in_range(value, _LENGTHS[name])
        elif name == "cover_even":
            ok = value is None or _in_range(value, _SPREAD_MAX)
        elif name in _SPACINGS:
            ok = _in_range(value, 1.0)
        else:
            raise ValueError(f"ObservationPolicy: unknown field {name!r}; the fields are "
                             f"{', '.join(f.name for f in fields(cls))}")
        if not ok:
            raise ValueError(f"{where}: must be {cls.field_range(name)}, got {value!r}")
        return (float(value[0]), float(value[1])) if name == "camera_bound" and value is not None else value

    @classmethod
    def field_range(cls, name: str) -> str:
        """What :meth:`check_field` accepts for the field ``name``, in words (its error messages' and the
        configuration reference's).

        Raises:
            ValueError: an unknown field.
        """
        if name == "camera_bound":
            return (f"(translation in (0, {_CAMERA_BOUND[0]:g}] m, rotation in (0, {_CAMERA_BOUND[1]:.3g}] rad) or "
                    "none")
        if name == "ray_smoothing":
            return f"{_RAYS[0]}-{_RAYS[1]} rays, or none"
        if name == "contact_repeats":
            return f"a whole number {_REPEATS[0]}-{_REPEATS[1]}"
        if name == "inside_halvings":
            return f"a whole number {_HALVINGS[0]}-{_HALVINGS[1]}"
        if name in _FLAGS:
            return "true or false"
        if name in _LENGTHS:
            return f"in (0, {_LENGTHS[name]:g}] m or none"
        if name == "cover_even":
            return f"a share of the median gap in (0, {_SPREAD_MAX:g}], or none"
        if name in _SPACINGS:
            return "in (0, 1] m"
        cls.check_field(name, None)         # raises, naming the fields
        return ""                           # pragma: no cover

    @property
    def ramp(self) -> float:
        """The distance [m] over which the labels rise from 0 on a surface to 1 in free space: the camera's
        free-space offset (the paper's 5 cm when that is None)."""
        return self.vision_free_offset or 0.05

    def inside_label(self, depth: float) -> float:
        """The label of a point ``depth`` [m] inside a body: ``-depth / ramp`` (:attr:`ramp`), the free-space ramp
        continued inside."""
        return -float(depth) / self.ramp

    def behind_contacts(self, contacts, normals) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The inside points :attr:`touch_inside` [m] behind ``contacts`` `(n, d)` [m] along their outward
        ``normals`` `(n, d)` (any length; a measured force's direction serves), as an exploration places one behind
        each touch: `(k, d)` points, `(k,)` labels (:meth:`inside_label`) and `(k,)` the indices of their contacts.
        None without the setting, and none for a contact whose normal is not finite or shorter than 0.5 (unit
        normals are expected; a zero one says the sensor measured no direction)."""
        contacts = np.asarray(contacts, dtype=np.float64)
        d = contacts.shape[-1] if contacts.ndim == 2 else 0
        none = np.empty((0, d)), np.empty(0), np.empty(0, dtype=np.int64)
        depth = self.touch_inside
        if depth is None or contacts.ndim != 2 or not len(contacts):
            return none
        normals = np.asarray(normals, dtype=np.float64).reshape(contacts.shape)
        length = np.linalg.norm(normals, axis=1)
        ok = np.isfinite(normals).all(axis=1) & (length >= 0.5)
        if not ok.any():
            return none
        index = np.flatnonzero(ok)
        points = contacts[index] - depth * normals[index] / length[index, None]
        return points, np.full(len(index), self.inside_label(depth)), index

    def inside_depth(self, label) -> np.ndarray:
        """The depth [m] an inside label stands for (the inverse of :meth:`inside_label`), elementwise."""
        return -np.asarray(label, dtype=np.float64) * self.ramp

    def with_voxel(self, voxel: float) -> "ObservationPolicy":
        """This policy with the camera's points averaged in voxels of edge ``voxel`` [m]; 0 keeps every point.

        Raises:
            ValueError: ``voxel`` negative, above 1 m or not a finite number.
        """
        return replace(self, voxel=check_voxel(voxel) or None)


#: Largest voxel edge accepted [m]: coarser than a metre averages a whole object into a point.
MAX_VOXEL = 1.0


def check_voxel(voxel) -> float:
    """``voxel`` [m] as a float: 0 (no averaging) or an edge in [``VOXEL_RANGE[0]``, ``MAX_VOXEL``] (the smallest
    edge the averaging takes, :data:`torch_gpioius.geometry.voxels.VOXEL_RANGE`); raises ValueError naming the value."""
    from ..geometry.voxels import VOXEL_RANGE

    if isinstance(voxel, bool) or not isinstance(voxel, (int, float)) or not (
            math.isfinite(voxel) and (voxel == 0 or VOXEL_RANGE[0] <= voxel <= MAX_VOXEL)):
        raise ValueError(f"voxel: must be 0 (keep every camera point) or an edge in [{VOXEL_RANGE[0]:g}, "
                         f"{MAX_VOXEL:g}] m, got {voxel!r}")
    return float(voxel)


#: The policy's on/off fields.
_FLAGS = ("cover_offset", "vision_inside_deep", "cover_gap_field", "camera_table", "cover_carry",
          "cover_uneven_field")
#: The policy's optional lengths [m] and the largest each takes (None: off).
_LENGTHS = {"vision_free_offset": 1.0, "voxel": MAX_VOXEL, "crop_margin": 10.0, "vision_free_far": 1.0,
            "touch_inside": INSIDE_DEPTH_MAX, "vision_inside": INSIDE_DEPTH_MAX, "vision_inside_gap": INSIDE_DEPTH_MAX}
#: The largest ``cover_even``: an interquartile range twice the median gap admits nearly any cover.
_SPREAD_MAX = 2.0
#: The policy's spacings along the fingertip's path [m], in (0, 1].
_SPACINGS = ("free_space_spacing", "free_space_margin")
#: The largest camera bound: (translation [m], rotation [rad]).
_CAMERA_BOUND = (0.1, math.radians(20))
#: The rays ``ray_smoothing`` may average over.
_RAYS = (8, 10_000)
#: The times ``contact_repeats`` may count a contact (64: a contact's noise down to a 64th of the camera's).
_REPEATS = (1, 64)
#: ObservationPolicy.inside_halvings' range: four halvings take 2 cm to 1.25 mm, below a voxel's noise.
_HALVINGS = (0, 4)


def _in_range(value, hi: float) -> bool:
    """Whether ``value`` is a finite number in (0, ``hi``] (a bool is not a number here)."""
    return (not isinstance(value, bool) and isinstance(value, (int, float)) and math.isfinite(value)
            and 0 < value <= hi)
