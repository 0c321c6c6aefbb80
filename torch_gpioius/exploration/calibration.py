"""The camera's captures corrected from the touches during an exploration (``ObservationPolicy.camera_bound``).

A run captures its views once, before the first touch. At :data:`CORRECT_AFTER` contacts, and again every
:data:`CORRECT_EVERY` more, each view's capture as first taken is moved rigidly about its camera to agree with all the
contacts so far and with the other views (:func:`~torch_gpioius.sensors.extrinsics.correct_captures`, the contacts'
normals the inner estimate's), within the bound the policy gives; the camera's observations in the model are replaced
by those of the corrected captures, labelled as the first ones were. More contacts fix more of the error (twenty
near the first touch leave 5-6 mm at the body's middle of 1-2.5 cm; the whole run's, less), so the correction is
done again as they come. Each replacement is an ordinary step batch (the old rows removed, the new ones added), so a
log replays it and a resumed run continues from it; the step's record says what each view was moved by.
"""

from __future__ import annotations

import numpy as np
import torch

from ..models.labels import ObservationPolicy
from ..geometry.differential import surface_geometry
from ..models.gpiois import OUTER
from .observations import Observations, vision_observations

__all__ = ["CORRECT_AFTER", "CORRECT_EVERY", "capture_views", "vision_crop", "contact_normals", "camera_table",
           "correct_at_start", "correct_camera"]

#: Contacts before the captures are first corrected: enough, spread over the body, that several lie under each view's
#: seen cover (a view with none is left to the overlaps and the bound's prior).
CORRECT_AFTER = 20
#: The captures corrected again (from their first capture, with every contact so far) every this many contacts more;
#: also the retry when too few lay under the seen cover (``CaptureCorrections.enough``).
CORRECT_EVERY = 20


def capture_views(camera) -> list:
    """Each view's capture of ``camera`` (a :class:`~torch_gpioius.sensors.pointcloud.MultiViewSource`'s views in
    order; one capture for a single camera): what ``camera.capture()`` merges."""
    sources = getattr(camera, "sources", None)
    return [s.capture() for s in sources] if sources else [camera.capture()]


def vision_crop(world, policy: ObservationPolicy) -> np.ndarray | None:
    """The box `(2, d)` the camera's cloud is cropped to: the world's, grown by ``policy.crop_margin`` (None: no
    crop)."""
    crop = world.crop_box()
    if crop is None or policy.crop_margin is None:
        return None
    return crop + np.array([[-policy.crop_margin], [policy.crop_margin]])


def contact_normals(model, contacts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The contacts where the inner estimate has a normal, `(k, d)`, and those unit outward normals `(k, d)`
    (:func:`~torch_gpioius.geometry.surface_geometry`: the gradient of the posterior mean; a contact where it vanishes
    has no direction to pair by and is left out)."""
    geo = surface_geometry(model, contacts, 0)
    defined = geo.normal_defined.cpu().numpy()
    return contacts[defined], geo.normal.cpu().numpy()[defined]


def camera_table(hardware, policy: ObservationPolicy) -> float | None:
    """The height [m] of the table a run's captures are held to when corrected (``policy.camera_table`` with a
    ``camera_bound``): the floor the hardware's contact controller keeps the fingertip above, or None."""
    if policy.camera_bound is None or not policy.camera_table:
        return None
    config = getattr(getattr(hardware, "controller", None), "config", None)
    floor = getattr(config, "floor", None)
    return None if floor is None else float(floor)


def _corrections(captures: list, contacts: np.ndarray, normals: np.ndarray | None, policy: ObservationPolicy,
                 crop: np.ndarray | None, table: float | None):
    """The captures cropped as the run crops them and :func:`~torch_gpioius.sensors.extrinsics.correct_captures`'
    corrections of them within ``policy.camera_bound`` (held to the ``table`` height as well, when given), or
    ``(captures, None)`` when a cropped capture keeps too few points or the corrections are not ``enough``."""
    from ..sensors.extrinsics import correct_captures

    if crop is not None:                  # what lies beyond the range (a wall, the table's far end) is not the cover
        captures = [c.cropped(crop[0], crop[1]) for c in captures]
    if any(len(c) < 10 for c in captures):
        return captures, None
    found = correct_captures(captures, contacts, normals, max_translation=policy.camera_bound[0],
                             max_rotation=policy.camera_bound[1], support=table)
    return captures, (found if found.enough else None)


def correct_at_start(captures: list, policy: ObservationPolicy, crop: np.ndarray | None,
                     table: float | None) -> tuple[list, dict | None]:
    """The views' captures corrected from the table alone, before the first touch (``policy.camera_bound`` and a
    ``table`` height [m], :func:`camera_table`): each capture's view of the table held to its plane fixes its height
    and its rotations about horizontal axes (a degree off a metre away lands the cover 1-2 cm off), the rest left to
    the calibration's prior and the views' overlaps; the contacts correct the whole pose later (:func:`correct_camera`,
    always from the captures as first taken).

    Returns:
        The captures to label the first observations with (corrected, or as given when nothing is due: no bound, no
        table, a capture that sees too little of it) and the correction's record, or None.
    """
    if policy.camera_bound is None or table is None or not captures or np.asarray(captures[0].points).shape[1] != 3:
        return captures, None
    from ..sensors.pointcloud import PointCloud

    _, found = _corrections(captures, np.zeros((0, 3)), None, policy, crop, table)
    if found is None:
        return captures, None
    return ([PointCloud(f.apply(c.points), c.origin) for c, f in zip(captures, found.captures)],
            found.as_record())


def correct_camera(model, captures: list, contacts: np.ndarray, policy: ObservationPolicy,
                   crop: np.ndarray | None,
                   table: float | None = None) -> tuple[np.ndarray, Observations | None, dict | None]:
    """Correct the views' captures from the contacts and replace the model's camera observations by theirs.

    Args:
        model: the run's GPIOIS (modified: its outer rows removed).
        captures: each view's :class:`~torch_gpioius.sensors.pointcloud.PointCloud` as first captured, base frame.
        contacts: `(k, 3)` the contacts so far [m].
        policy: the run's policy (``camera_bound``, and the labels the new observations get).
        crop: the box the cloud is cropped to (:func:`vision_crop`).
        table: the height [m] of the table (:func:`camera_table`) each capture's table points
            (``PointCloud.support``, not cropped) are held to; None: none.

    Returns:
        ``(removed, observations, record)``: the indices of the rows removed (into the model's data before the call),
        the new camera observations (task outer, source "camera-corrected") and the correction's record
        (:meth:`~torch_gpioius.sensors.extrinsics.CaptureCorrections.as_record`); ``(empty, None, None)`` when
        nothing is due (no bound, a model without an outer task, a 2-D world; a contact count other than
        :data:`CORRECT_AFTER` plus a multiple of :data:`CORRECT_EVERY`; too few contacts under the seen cover).
    """
    none = np.zeros(0, dtype=np.int64), None, None
    due = len(contacts) >= CORRECT_AFTER and (len(contacts) - CORRECT_AFTER) % CORRECT_EVERY == 0
    if (policy.camera_bound is None or not captures or not due or getattr(model, "num_tasks", 1) < 2
            or np.asarray(contacts).shape[1] != 3):
        return none
    from ..sensors.pointcloud import PointCloud

    contacts = np.asarray(contacts, dtype=np.float64)
    captures, found = _corrections(captures, *contact_normals(model, contacts), policy, crop, table)
    if found is None:                     # too few contacts under the seen cover yet: tried again later
        return none
    moved = PointCloud.merge([PointCloud(f.apply(c.points), c.origin) for c, f in zip(captures, found.captures)])
    x, y = vision_observations(moved, policy, crop)
    outer = (model.train_inputs[1].squeeze(-1) == OUTER).cpu().numpy()
    model.remove_observations(torch.as_tensor(outer))
    return (np.flatnonzero(outer), Observations(x, y, np.ones(len(y), np.int64), source="camera-corrected"),
            found.as_record())
