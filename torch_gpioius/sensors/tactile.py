r"""Vision-based tactile sensors (DIGIT, GelSight, GelSlim): one reading is a depth map of the gel pad.

**Frames and sign conventions.** The pad frame has its origin at the centre of the undeformed gel surface, its
z axis along the pad's outward normal (from the sensor into what it touches), x along the image's columns and y
along its rows. ``pose`` maps pad coordinates to the base frame (a `(4, 4)` rigid transform).

**A reading.** ``depth[i, j]`` [m] is how far the gel surface at pixel (i, j) is pressed in, along -z: 0 untouched,
``gel_thickness`` fully pressed; NaN where the gel touched nothing (no reconstruction there). The touched
surface at that pixel is the pad point

    p_ij = ((j - (W - 1) / 2) pitch, (i - (H - 1) / 2) pitch, -depth[i, j]).

A pixel counts as a contact where ``depth >= contact_depth``; pressed less (or NaN) it saw no object, and the
undeformed gel there is free space. How a reading becomes surface points with normals and free space is
:func:`torch_gpioius.exploration.patches.patch_observations`.

**Calibration** is explicit (:class:`TactileCalibration`): the pixel pitch [m/px] on the gel, the gel's thickness
(the deepest indentation it can report: its reach) and the contact depth. Hardware adapters:

* :class:`DepthMapTactileSensor`: any source of depth maps and poses (a ROS 2 bag's ``sensor_msgs/Image`` depth
  topic through :func:`depth_from_image_message`, a simulator, a recorded array);
* :class:`DigitTactileSensor`: a DIGIT through ``digit-interface`` (``digit_interface.Digit``), with a
  user-supplied image-to-depth function (DIGIT reports RGB images; turning them into depth is a calibrated model
  of its own, e.g. a look-up table or a network, which this library does not ship).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Callable, Protocol, runtime_checkable

import numpy as np

__all__ = ["TactileCalibration", "TactileReading", "TactileSensor", "DepthMapTactileSensor", "DigitTactileSensor",
           "depth_from_image_message", "DIGIT_CALIBRATION"]


@dataclass(frozen=True)
class TactileCalibration:
    """The geometry of a gel pad.

    Attributes:
        pitch: size of one pixel on the gel [m/px].
        gel_thickness: deepest indentation the gel can report (its reach) [m].
        contact_depth: a pixel with at least this indentation is a contact [m]; below it the gel saw nothing.

    Raises:
        ValueError: a value that is not a positive finite number of metres, or ``contact_depth >= gel_thickness``.
    """

    pitch: float
    gel_thickness: float
    contact_depth: float

    def __post_init__(self) -> None:
        for name in ("pitch", "gel_thickness", "contact_depth"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not (math.isfinite(v) and 0 < v < 0.1):
                raise ValueError(f"TactileCalibration.{name}: must be a positive number of metres below 0.1, got {v!r}")
        if self.contact_depth >= self.gel_thickness:
            raise ValueError(f"TactileCalibration: contact_depth {self.contact_depth:g} m must be below the gel "
                             f"thickness {self.gel_thickness:g} m")

    @property
    def reach(self) -> float:
        """The deepest indentation a reading may hold [m] (the gel's thickness)."""
        return self.gel_thickness


#: A DIGIT-like pad: 240 x 320 px over about 16 x 21 mm (pitch ~ 66 um), 2.5 mm gel, contact at 0.1 mm.
DIGIT_CALIBRATION = TactileCalibration(pitch=6.6e-5, gel_thickness=2.5e-3, contact_depth=1e-4)

#: Rounding allowed on the reach and on the rigidity of a pose.
_TOL = 1e-9


@dataclass
class TactileReading:
    """One frame of a tactile pad (see the module docstring for the frames).

    Attributes:
        depth: `(H, W)` indentation [m], NaN where the gel touched nothing.
        pose: `(4, 4)` pad-to-base rigid transform [m].
        calibration: the pad's :class:`TactileCalibration`.
        stamp: time of the frame [s].

    Raises:
        ValueError: a depth map that is not 2-D (at least 2 x 2), holds inf or indentations outside
            ``[0, reach]``; a pose that is not a finite `(4, 4)` rigid transform. Each message names the field.
    """

    depth: np.ndarray
    pose: np.ndarray
    calibration: TactileCalibration
    stamp: float = field(default=0.0)

    def __post_init__(self) -> None:
        if not isinstance(self.calibration, TactileCalibration):
            raise ValueError(f"TactileReading.calibration: expected a TactileCalibration, got "
                             f"{type(self.calibration).__name__}")
        depth = np.asarray(self.depth, dtype=np.float64)
        if depth.ndim != 2 or min(depth.shape) < 2:
            raise ValueError(f"TactileReading.depth: expected an (H, W) depth map with H, W >= 2, got shape "
                             f"{depth.shape}")
        if np.isinf(depth).any():
            raise ValueError("TactileReading.depth: contains inf (NaN marks pixels that touched nothing)")
        known = depth[np.isfinite(depth)]
        if known.size and (known.min() < -_TOL or known.max() > self.calibration.reach + _TOL):
            raise ValueError(f"TactileReading.depth: indentations from {known.min() * 1e3:.3g} to "
                             f"{known.max() * 1e3:.3g} mm lie outside the gel's reach [0, "
                             f"{self.calibration.reach * 1e3:.3g}] mm (units? calibration?)")
        pose = np.asarray(self.pose, dtype=np.float64)
        if pose.shape != (4, 4) or not np.isfinite(pose).all():
            raise ValueError(f"TactileReading.pose: expected a finite (4, 4) transform, got shape {pose.shape}"
                             + ("" if pose.shape != (4, 4) else " with NaN or inf"))
        rot = pose[:3, :3]
        if (not np.allclose(rot.T @ rot, np.eye(3), atol=1e-6) or abs(np.linalg.det(rot) - 1) > 1e-6
                or not np.allclose(pose[3], [0, 0, 0, 1], atol=_TOL)):
            raise ValueError("TactileReading.pose: not a rigid transform (rotation must be orthonormal with "
                             "determinant 1, last row [0, 0, 0, 1])")
        if isinstance(self.stamp, bool) or not isinstance(self.stamp, (int, float)) or not math.isfinite(self.stamp):
            raise ValueError(f"TactileReading.stamp: must be a finite time [s], got {self.stamp!r}")
        self.depth, self.pose, self.stamp = depth, pose, float(self.stamp)

    @property
    def shape(self) -> tuple[int, int]:
        return self.depth.shape

    @property
    def contact_mask(self) -> np.ndarray:
        """`(H, W)` bool: pixels pressed at least ``contact_depth``."""
        with np.errstate(invalid="ignore"):
            return np.nan_to_num(self.depth, nan=-1.0) >= self.calibration.contact_depth

    def pixel_points(self) -> np.ndarray:
        """`(H, W, 3)` pad-frame points of every pixel's touched surface (z = -depth; NaN depth gives z = 0: the
        undeformed gel)."""
        h, w = self.depth.shape
        pitch = self.calibration.pitch
        jj, ii = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
        return np.stack([(jj - (w - 1) / 2) * pitch, (ii - (h - 1) / 2) * pitch,
                         -np.nan_to_num(self.depth, nan=0.0)], axis=-1)

    def to_base(self, points: np.ndarray, directions: bool = False) -> np.ndarray:
        """Pad-frame points (or directions) `(..., 3)` in the base frame."""
        rot, t = self.pose[:3, :3], self.pose[:3, 3]
        out = np.asarray(points, dtype=np.float64) @ rot.T
        return out if directions else out + t


@runtime_checkable
class TactileSensor(Protocol):
    """Any tactile pad: ``calibration`` and ``read()`` returning the current :class:`TactileReading`."""

    calibration: TactileCalibration

    def read(self) -> TactileReading: ...


class DepthMapTactileSensor:
    """A tactile sensor from any source of depth maps (a simulator, a recorded bag, an array).

    Args:
        frames: ``() -> (depth (H, W) [m], pose (4, 4))``, the current frame.
        calibration: the pad's calibration.
        shape: the expected `(H, W)`; a frame of another shape is refused (a wrong topic or a resized stream).
        clock: time source for stamps [s].
    """

    def __init__(self, frames: Callable[[], tuple], calibration: TactileCalibration,
                 shape: tuple[int, int] | None = None, clock: Callable[[], float] = time.monotonic):
        if not callable(frames):
            raise ValueError(f"frames: expected a callable returning (depth, pose), got {type(frames).__name__}")
        self.frames, self.calibration, self.clock = frames, calibration, clock
        self.shape = None if shape is None else tuple(int(v) for v in shape)

    def read(self) -> TactileReading:
        """The current frame as a checked :class:`TactileReading`.

        Raises:
            ValueError: the frame is malformed (see :class:`TactileReading`) or not of ``shape``.
        """
        depth, pose = self.frames()
        depth = np.asarray(depth, dtype=np.float64)
        if self.shape is not None and depth.shape != self.shape:
            raise ValueError(f"tactile frame: depth map of shape {depth.shape}, expected {self.shape}")
        return TactileReading(depth, pose, self.calibration, self.clock())


class DigitTactileSensor(DepthMapTactileSensor):
    """A DIGIT (or any camera-based pad) through ``digit-interface``.

    Args:
        digit: a connected ``digit_interface.Digit`` (or anything with ``get_frame() -> (H, W, 3) uint8``).
        image_to_depth: the user's calibrated model, ``(H, W, 3) image -> (H, W) indentation [m]`` (NaN where
            nothing touched). DIGIT reports colour images; their depth comes from a per-sensor calibration this
            library does not ship.
        pose: ``() -> (4, 4)`` the pad's current pose in the base frame (e.g. the robot's flange pose times the
            pad's mounting transform).
        calibration: the pad's calibration (default :data:`DIGIT_CALIBRATION`).
    """

    def __init__(self, digit, image_to_depth: Callable[[np.ndarray], np.ndarray], pose: Callable[[], np.ndarray],
                 calibration: TactileCalibration = DIGIT_CALIBRATION, clock: Callable[[], float] = time.monotonic):
        if not callable(getattr(digit, "get_frame", None)):
            raise ValueError("digit: expected a digit_interface.Digit (an object with get_frame())")
        if not callable(image_to_depth) or not callable(pose):
            raise ValueError("image_to_depth and pose: must be callables")
        self.digit, self.image_to_depth, self.pose = digit, image_to_depth, pose

        def frames():
            image = np.asarray(digit.get_frame())
            if image.ndim != 3 or image.shape[2] != 3:
                raise ValueError(f"DIGIT frame: expected an (H, W, 3) colour image, got shape {image.shape}")
            depth = np.asarray(image_to_depth(image), dtype=np.float64)
            if depth.shape != image.shape[:2]:
                raise ValueError(f"image_to_depth: returned shape {depth.shape} for an image of {image.shape[:2]}")
            return depth, pose()

        super().__init__(frames, calibration, None, clock)


#: Depth encodings of ``sensor_msgs/Image`` and their scale to metres.
_DEPTH_ENCODINGS = {"32FC1": (np.float32, 1.0), "64FC1": (np.float64, 1.0), "16UC1": (np.uint16, 1e-3),
                    "mono16": (np.uint16, 1e-3)}


def depth_from_image_message(msg, invalid_zero: bool = True) -> np.ndarray:
    """A ``sensor_msgs/Image`` depth frame (as ``rosbags`` deserialises it) as an `(H, W)` array [m].

    Args:
        msg: the message (``height``, ``width``, ``encoding``, ``is_bigendian``, ``step``, ``data``).
        invalid_zero: integer encodings mark "no reading" with 0; map those to NaN.

    Raises:
        ValueError: an encoding that is not a depth encoding (32FC1, 64FC1, 16UC1 [mm], mono16 [mm]), or a data
            size that does not match height, width and step.
    """
    enc = str(msg.encoding)
    if enc not in _DEPTH_ENCODINGS:
        raise ValueError(f"sensor_msgs/Image: encoding {enc!r} is not a depth encoding; expected one of "
                         f"{sorted(_DEPTH_ENCODINGS)}")
    dtype, scale = _DEPTH_ENCODINGS[enc]
    dt = np.dtype(dtype).newbyteorder(">" if msg.is_bigendian else "<")
    h, w, step = int(msg.height), int(msg.width), int(msg.step)
    data = np.frombuffer(bytes(msg.data), dtype=np.uint8)
    if h < 1 or w < 1 or step < w * dt.itemsize or data.size != h * step:
        raise ValueError(f"sensor_msgs/Image: {data.size} bytes do not hold {h} rows of step {step} "
                         f"({w} pixels of {dt.itemsize} bytes)")
    rows = data.reshape(h, step)[:, :w * dt.itemsize]
    img = np.ascontiguousarray(rows).view(dt).reshape(h, w).astype(np.float64) * scale
    if invalid_zero and np.issubdtype(dtype, np.integer):
        img[img == 0] = np.nan
    return img
