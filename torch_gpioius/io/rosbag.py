"""Import a ROS 2 bag (MCAP or sqlite3) recorded on a UR5 with a depth camera and a fingertip force sensor.

The bag is read with `rosbags <https://gitlab.com/ternaris/rosbags>`_ (pure Python, no ROS install). What becomes
what:

* **Inner (touch, task 0).** For every ``geometry_msgs/WrenchStamped`` sample the fingertip position is the UR5's
  forward kinematics (the project's CB3 model and ``tool_offset``) at the ``sensor_msgs/JointState`` positions
  linearly interpolated to the wrench's time. ``|F| >= contact_force`` (1 N, Sec. VI) is a contact (y = 0),
  thinned to ``contact_spacing``; below it the fingertip was in free space (y = 1), thinned with the exploration's
  own rule (:func:`torch_gpioius.exploration.observations.thin_points`: ``free_space_spacing`` apart and
  ``free_space_margin`` away from every contact).
* **Outer (vision, task 1, step 0).** Every ``sensor_msgs/PointCloud2`` is decoded (any field layout, organised or
  not, NaN points dropped), moved to the base frame through ``/tf_static`` (and ``/tf``) or a transform given by
  the caller, and then goes through the exploration's vision rule
  (:func:`torch_gpioius.exploration.observations.vision_observations`): the seen surface (y = 0) and free space
  ``vision_free_offset`` in front of it towards the camera (y = 1), averaged in ``voxel`` cubes (paper: 5 cm).

Times are the messages' header stamps (the sensor's clock), or the bag's receive time where a stamp is zero.
Every problem with a bag raises :class:`BagImportError` with one line naming the topic and the cause.
"""

from __future__ import annotations

import dataclasses
import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import numpy as np
import torch

from ..core.validation import as_bounds
from .datasets import Dataset, DatasetError

__all__ = ["BagImportError", "BagTopics", "BagMessage", "import_bag", "decode_point_cloud2", "parse_transform",
           "write_bag"]

#: ``sensor_msgs/PointField`` datatype codes -> numpy scalar types.
_POINTFIELD_DTYPES = {1: "i1", 2: "u1", 3: "i2", 4: "u2", 5: "i4", 6: "u4", 7: "f4", 8: "f8"}
_TYPES = {
    "cloud": "sensor_msgs/msg/PointCloud2",
    "wrench": "geometry_msgs/msg/WrenchStamped",
    "joints": "sensor_msgs/msg/JointState",
    "tf": "tf2_msgs/msg/TFMessage",
    "tactile": "sensor_msgs/msg/Image",
}


class BagImportError(DatasetError):
    """A bag that cannot be imported; the message names the topic and the cause."""


@dataclass(frozen=True)
class BagTopics:
    """Topic names in the bag.

    Attributes:
        cloud: ``sensor_msgs/PointCloud2`` of the depth camera (outer shape).
        wrench: ``geometry_msgs/WrenchStamped`` of the fingertip force sensor.
        joints: ``sensor_msgs/JointState`` of the UR5 (names as in the UR driver, e.g. ``shoulder_pan_joint``).
        tf: ``tf2_msgs/TFMessage`` topics to take the camera's pose from; missing ones are skipped.
        tactile: ``sensor_msgs/Image`` depth maps of a gel pad at the fingertip (DIGIT, GelSight; 32FC1 / 64FC1 in
            metres or 16UC1 / mono16 in mm, as :func:`torch_gpioius.sensors.tactile.depth_from_image_message`), or
            None: no pad.
    """

    cloud: str = "/camera/depth/points"
    wrench: str = "/wrench"
    joints: str = "/joint_states"
    tf: tuple[str, ...] = ("/tf_static", "/tf")
    tactile: str | None = None


# ----------------------------------------------------------------------------------------------- point clouds
#: Largest plausible distance of a depth-camera point from its optical frame [m]: a point beyond it was decoded
#: with the wrong byte order or datatype (a Kinect sees to ~5 m, a lidar to a few hundred).
MAX_CLOUD_RANGE = 1000.0


def decode_point_cloud2(msg, *, topic: str = "PointCloud2", max_range: float = MAX_CLOUD_RANGE) -> np.ndarray:
    """The finite x, y, z points of a ``sensor_msgs/PointCloud2`` in its own frame.

    Handles any field order and padding (``point_step``), row padding of organised clouds (``row_step``), both
    byte orders, float32/float64 and integer coordinates; points with a NaN or inf coordinate are dropped (an
    organised cloud marks missing depth so).

    Args:
        msg: the deserialised message (``rosbags`` dataclass or anything with the same attributes).
        topic: used in error messages.
        max_range: a finite point farther than this from the frame's origin [m] means the bytes were decoded
            wrongly (the ``is_bigendian`` flag or a datatype does not match the data): refused, never imported.

    Returns:
        `(n, 3)` float64 [m] in ``msg.header.frame_id``.

    Raises:
        BagImportError: no x/y/z field, a repeated field name, x/y/z fields whose bytes overlap, a field with
            count != 1, sizes that do not match the data, implausible coordinates.
    """
    names_all = [f.name for f in msg.fields]
    repeated = sorted({n for n in names_all if names_all.count(n) > 1})
    if repeated:
        raise BagImportError(f"{topic}: the point cloud declares field {repeated[0]!r} {names_all.count(repeated[0])} "
                             f"times (fields: {', '.join(names_all)}); which one holds the data is ambiguous")
    fields = {f.name: f for f in msg.fields}
    missing = [c for c in "xyz" if c not in fields]
    if missing:
        raise BagImportError(f"{topic}: the point cloud has no {'/'.join(missing)} field "
                             f"(fields: {', '.join(fields) or 'none'})")
    height, width, step, row_step = int(msg.height), int(msg.width), int(msg.point_step), int(msg.row_step)
    data = np.asarray(msg.data, dtype=np.uint8)
    if height * width == 0:
        return np.zeros((0, 3))
    if row_step < width * step or data.size < height * row_step:
        raise BagImportError(f"{topic}: the point cloud's data ({data.size} bytes) does not hold {height} x {width} "
                             f"points of {step} bytes (row_step {row_step})")
    order = ">" if msg.is_bigendian else "<"
    names, formats, offsets, spans = [], [], [], []
    for c in "xyz":
        f = fields[c]
        if int(f.datatype) not in _POINTFIELD_DTYPES or int(f.count) != 1:
            raise BagImportError(f"{topic}: field {c!r} has datatype {f.datatype} and count {f.count}; expected one "
                                 "number (PointField datatypes 1-8)")
        names.append(c)
        formats.append(order + _POINTFIELD_DTYPES[int(f.datatype)])
        offsets.append(int(f.offset))
        size = np.dtype(formats[-1]).itemsize
        if int(f.offset) < 0 or int(f.offset) + size > step:
            raise BagImportError(f"{topic}: field {c!r} at offset {f.offset} lies beyond point_step {step}")
        spans.append((int(f.offset), int(f.offset) + size, c))
    spans.sort()
    for (a0, a1, ca), (b0, b1, cb) in zip(spans[:-1], spans[1:]):
        if b0 < a1:
            raise BagImportError(f"{topic}: fields {ca!r} (bytes {a0}-{a1 - 1}) and {cb!r} (bytes {b0}-{b1 - 1}) "
                                 "overlap; each coordinate needs its own bytes")
    dtype = np.dtype({"names": names, "formats": formats, "offsets": offsets, "itemsize": step})
    rows = data[:height * row_step].reshape(height, row_step)[:, :width * step]
    pts = np.ascontiguousarray(rows).view(dtype).reshape(-1)
    xyz = np.stack([pts[c].astype(np.float64) for c in "xyz"], axis=1)
    xyz = xyz[np.isfinite(xyz).all(axis=1)]
    if len(xyz):
        far = np.linalg.norm(xyz, axis=1) > max_range
        if far.any():
            raise BagImportError(f"{topic}: {int(far.sum())} of {len(xyz)} points lie farther than {max_range:g} m "
                                 f"from the camera (up to {float(np.abs(xyz).max()):.3g} m): the data do not decode "
                                 f"as the message declares (is_bigendian={bool(msg.is_bigendian)}, datatypes "
                                 f"{[int(fields[c].datatype) for c in 'xyz']}); check the recorder's byte order")
    return xyz


# ----------------------------------------------------------------------------------------------- transforms
def _quat_matrix(q: Sequence[float]) -> np.ndarray:
    x, y, z, w = (float(v) for v in q)
    n = math.sqrt(x * x + y * y + z * z + w * w)
    if not math.isfinite(n) or n < 1e-9:
        raise ValueError(f"quaternion {tuple(q)} (x, y, z, w) is not a rotation")
    x, y, z, w = x / n, y / n, z / n, w / n
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def _homogeneous(t: Sequence[float], q: Sequence[float]) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = _quat_matrix(q)
    T[:3, 3] = np.asarray(t, dtype=np.float64)
    return T


def parse_transform(value) -> np.ndarray:
    """A `(4, 4)` transform from ``"x y z qx qy qz qw"`` (ROS ``static_transform_publisher`` order, metres, a unit
    quaternion), from 7 numbers, or from a `(4, 4)` matrix.

    Raises:
        ValueError: anything else (wrong count, NaN, a zero quaternion, a matrix that is not rigid).
    """
    if isinstance(value, str):
        parts = value.replace(",", " ").split()
        try:
            value = [float(p) for p in parts]
        except ValueError:
            raise ValueError(f"transform {value!r}: expected 7 numbers 'x y z qx qy qz qw'") from None
    a = np.asarray(value, dtype=np.float64)
    if a.shape == (7,):
        if not np.isfinite(a).all():
            raise ValueError(f"transform {a.tolist()}: contains NaN or inf")
        return _homogeneous(a[:3], a[3:])
    if a.shape == (4, 4):
        R = a[:3, :3]
        if (not np.isfinite(a).all() or not np.allclose(R @ R.T, np.eye(3), atol=1e-6)
                or abs(np.linalg.det(R) - 1) > 1e-6 or not np.allclose(a[3], [0, 0, 0, 1])):
            raise ValueError("transform: a (4, 4) matrix must be rigid (orthonormal rotation, last row 0 0 0 1)")
        return a.copy()
    raise ValueError(f"transform: expected 'x y z qx qy qz qw', 7 numbers or a (4, 4) matrix, got shape {a.shape}")


class _TfBuffer:
    """Parent links from TFMessages: static ones, and dynamic ones looked up at the latest stamp not after t."""

    def __init__(self) -> None:
        self.links: dict[str, tuple[str, list[tuple[float, np.ndarray]]]] = {}

    def add(self, parent: str, child: str, stamp: float, T: np.ndarray, static: bool) -> None:
        parent, child = parent.lstrip("/"), child.lstrip("/")
        entry = self.links.setdefault(child, (parent, []))
        if entry[0] != parent:
            raise BagImportError(f"tf: frame {child!r} has two parents ({entry[0]!r} and {parent!r})")
        entry[1].append((-math.inf if static else stamp, T))

    def lookup(self, target: str, source: str, t: float) -> np.ndarray:
        """``T_target_source`` at time ``t``: follows parents from both frames to a common ancestor."""
        def chain(frame: str) -> list[tuple[str, np.ndarray]]:
            # [(frame, I), (parent, T_parent_frame), (grandparent, T_grandparent_parent), ...]
            out, seen = [(frame, np.eye(4))], {frame}
            while frame in self.links:
                parent, samples = self.links[frame]
                before = [s for s in samples if s[0] <= t]
                if not before:
                    break
                out.append((parent, max(before, key=lambda s: s[0])[1]))
                if parent in seen:
                    raise BagImportError(f"tf: the frames form a loop at {parent!r}")
                seen.add(parent)
                frame = parent
            return out

        def to_root(links: list[tuple[str, np.ndarray]]) -> dict[str, np.ndarray]:
            # T_frame_0 for every ancestor frame of the chain's first frame
            acc, out = np.eye(4), {links[0][0]: np.eye(4)}
            for frame, T_parent_child in links[1:]:
                acc = T_parent_child @ acc
                out[frame] = acc
            return out

        src, tgt = to_root(chain(source.lstrip("/"))), to_root(chain(target.lstrip("/")))
        common = [f for f in src if f in tgt]
        if not common:
            raise LookupError(
                f"no transform from {source!r} to {target!r} at t = {t:.3f} s in the bag's tf "
                f"(known frames: {', '.join(sorted(set(self.links) | {p for p, _ in self.links.values()})) or 'none'})"
            )
        f = common[0]
        return np.linalg.inv(tgt[f]) @ src[f]


# ----------------------------------------------------------------------------------------------- reading
def _stamp(msg, bag_time_ns: int) -> float:
    h = getattr(msg, "header", None)
    if h is not None and (h.stamp.sec or h.stamp.nanosec):
        return h.stamp.sec + h.stamp.nanosec * 1e-9
    return bag_time_ns * 1e-9


def _open(path: Path):
    try:
        from rosbags.highlevel import AnyReader
        from rosbags.typesys import Stores, get_typestore
    except ImportError as exc:  # pragma: no cover - the extra is missing
        from ..core.extras import install_hint

        raise ImportError(f"import_bag needs the 'rosbag' extra: {install_hint('rosbag')}") from exc
    if not path.exists():
        raise BagImportError(f"{path}: no such bag")
    try:
        reader = AnyReader([path], default_typestore=get_typestore(Stores.ROS2_HUMBLE))
        reader.open()
    except Exception as exc:  # rosbags raises its own error types for every kind of unreadable bag
        raise BagImportError(f"{path}: not a readable ROS 2 bag ({type(exc).__name__}: {exc})") from None
    return reader


def _connections(reader, path: Path, topic: str, kind: str, *, required: bool = True) -> list:
    conns = [c for c in reader.connections if c.topic == topic]
    if not conns:
        if not required:
            return []
        have = ", ".join(sorted({f"{c.topic} ({c.msgtype})" for c in reader.connections})) or "none"
        raise BagImportError(f"{path}: topic {topic} is not in the bag (topics: {have})")
    wrong = [c.msgtype for c in conns if c.msgtype != _TYPES[kind]]
    if wrong:
        raise BagImportError(f"{path}: topic {topic} carries {wrong[0]}, expected {_TYPES[kind]}")
    return conns


def _iter_messages(reader, path: Path, topic: str, kind: str, *, required: bool = True):
    """``(time [s], message)`` of a topic one at a time (nothing is held), checked: the type, a decodable message,
    a clock that never runs backwards, and (``required``) at least one message."""
    conns = _connections(reader, path, topic, kind, required=required)
    if not conns:
        return
    last, count = -math.inf, 0
    try:
        for conn, t_ns, raw in reader.messages(connections=conns):
            msg = reader.deserialize(raw, conn.msgtype)
            t = _stamp(msg, t_ns) if kind != "tf" else t_ns * 1e-9
            if kind != "tf" and t < last:
                raise BagImportError(f"{path}: topic {topic}: the clock runs backwards at message {count} "
                                     f"({last:.6f} s -> {t:.6f} s)")
            last, count = t, count + 1
            yield t, msg
    except BagImportError:
        raise
    except Exception as exc:
        raise BagImportError(f"{path}: topic {topic}: cannot decode a message ({type(exc).__name__}: {exc})") from None
    if required and not count:
        raise BagImportError(f"{path}: topic {topic} has no messages")


def _messages(reader, path: Path, topic: str, kind: str, *, required: bool = True) -> list[tuple[float, object]]:
    """Every message of a (small) topic, as :func:`_iter_messages` checks them."""
    return list(_iter_messages(reader, path, topic, kind, required=required))


#: Fastest joint speed of a UR5 (CB3 and e-Series: 180 deg/s on every joint) [rad/s].
UR5_MAX_JOINT_SPEED = math.pi
#: Joint states may imply speeds up to this factor above the limit before they are refused (stamps jitter).
JOINT_SPEED_SLACK = 1.25


def _joint_table(path: Path, topic: str, msgs: list, names: Sequence[str],
                 max_joint_speed: float = UR5_MAX_JOINT_SPEED) -> tuple[np.ndarray, np.ndarray]:
    """`(m,)` times and `(m, 6)` joint positions in ``names`` order, checked.

    A message that names a joint twice is refused (which copy is the joint's is ambiguous: taking the last one put
    contacts ~0.6 m off). So is a pair of consecutive states that would need a joint faster than
    ``max_joint_speed`` (by more than :data:`JOINT_SPEED_SLACK`): the robot cannot move so, and bags carry no
    checksums, so this is how a flipped bit in a joint value shows.
    """
    times, rows = [], []
    for t, msg in msgs:
        listed = list(msg.name)
        twice = sorted({n for n in listed if listed.count(n) > 1})
        if twice:
            raise BagImportError(f"{path}: topic {topic}: the joint state at t = {t:.6f} s names joint {twice[0]!r} "
                                 f"{listed.count(twice[0])} times; which value is the joint's is ambiguous")
        index = {n: i for i, n in enumerate(listed)}
        absent = [n for n in names if n not in index]
        if absent:
            raise BagImportError(f"{path}: topic {topic}: joint {absent[0]!r} is missing (names: "
                                 f"{', '.join(msg.name) or 'none'})")
        pos = np.asarray(msg.position, dtype=np.float64)
        if pos.shape != (len(msg.name),):
            raise BagImportError(f"{path}: topic {topic}: {len(msg.name)} names but {pos.size} positions")
        row = pos[[index[n] for n in names]]
        if not np.isfinite(row).all():
            raise BagImportError(f"{path}: topic {topic}: a joint position at t = {t:.6f} s is NaN or inf")
        times.append(t)
        rows.append(row)
    times, q = np.asarray(times), np.asarray(rows)
    if len(times) > 1:
        dq, dt = np.abs(np.diff(q, axis=0)), np.diff(times)[:, None]
        with np.errstate(divide="ignore", invalid="ignore"):
            speed = np.where(dq > 0, dq / dt, 0.0)
        limit = max_joint_speed * JOINT_SPEED_SLACK
        if (speed > limit).any():
            i, j = np.unravel_index(int(np.argmax(speed)), speed.shape)
            raise BagImportError(f"{path}: topic {topic}: joint {names[j]!r} moves {dq[i, j]:.4g} rad in "
                                 f"{dt[i, 0]:.4g} s at t = {times[i]:.6f} s ({speed[i, j]:.3g} rad/s; the robot's "
                                 f"limit is {max_joint_speed:.3g} rad/s): a corrupt joint value")
    return times, q


def _interpolate(path: Path, topic: str, t_joint: np.ndarray, q: np.ndarray, t: np.ndarray,
                 max_gap: float) -> np.ndarray:
    """Joint positions at times ``t`` by linear interpolation, refusing extrapolation and long gaps."""
    if len(t_joint) < 2:
        raise BagImportError(f"{path}: topic {topic}: {len(t_joint)} joint state(s); interpolation needs two")
    i = np.searchsorted(t_joint, t, side="right")
    outside = (i == 0) | ((i == len(t_joint)) & (t > t_joint[-1]))
    if outside.any():
        k = int(np.flatnonzero(outside)[0])
        raise BagImportError(f"{path}: topic {topic}: a wrench at t = {t[k]:.6f} s lies outside the joint states "
                             f"({t_joint[0]:.6f} - {t_joint[-1]:.6f} s)")
    i = np.clip(i, 1, len(t_joint) - 1)
    t0, t1 = t_joint[i - 1], t_joint[i]
    gap = t1 - t0
    if (gap > max_gap).any():
        k = int(np.argmax(gap))
        raise BagImportError(f"{path}: topic {topic}: a gap of {gap[k]:.3f} s between joint states at "
                             f"t = {t0[k]:.6f} s exceeds max_gap = {max_gap:g} s")
    w = np.where(gap > 0, (t - t0) / np.where(gap > 0, gap, 1.0), 0.0)[:, None]
    return q[i - 1] * (1 - w) + q[i] * w


def _window_text(w0: float, w1: float) -> str:
    return f"{w0:g}-{w1:g} s" if w1 < 1e11 else f"from {w0:g} s on"


def import_bag(bag: str | os.PathLike, *, settings=None, topics: BagTopics | None = None, base_frame: str = "base",
               camera_transform=None, tool_offset: Sequence[float] = (0.0, 0.0, 0.0), tip_radius: float = 0.0,
               contact_force: float = 1.0, contact_spacing: float = 0.005, max_gap: float = 0.1,
               joint_names: Sequence[str] | None = None, crop=None, time_window=None,
               max_joint_speed: float = UR5_MAX_JOINT_SPEED, tactile_calibration=None, tactile_transform=None,
               patch=None, camera_bound=None, camera_mount: str | None = None, **deprecated) -> Dataset:
    """Read a ROS 2 bag into a :class:`Dataset` that ``gpioius fit`` / ``replay`` and :func:`load_dataset` accept.

    Args:
        bag: the bag folder (sqlite3 or MCAP, with ``metadata.yaml``) or a single ``.mcap`` / ``.db3`` file.
        topics: topic names (:class:`BagTopics` defaults).
        base_frame: the robot's base frame name in tf (the UR driver's ``base``; ``base_link`` in some setups).
        camera_transform: ``T_base_cloudframe`` as ``"x y z qx qy qz qw"``, 7 numbers or a `(4, 4)` matrix; given,
            it replaces the tf lookup for the clouds (a camera calibrated outside ROS).
        tool_offset: `(3,)` fingertip centre in the flange frame [m] (as :class:`kinematics.UR5`).
        tip_radius: radius of the fingertip [m]; the contact point is the tip centre moved ``tip_radius``
            against the measured force (the wrench is taken to be in the tool frame). 0 keeps the tip centre.
        contact_force: ``|F|`` at and above which a sample is a contact [N] (Sec. VI: 1.0).
        contact_spacing: contacts closer than this to a kept earlier one are dropped [m].
        max_gap: the longest gap between joint states the interpolation bridges [s].
        joint_names: the six joint names in base-to-tool order (default: the UR driver's).
        crop: `(2, 3)` box `[min; max]` [m] to crop the cloud to (tables and walls are not the object); None keeps all.
        time_window: ``(start, end)`` [s] after the first wrench sample: only wrench samples and clouds stamped
            inside it are imported (joint states and tf are read whole, for interpolation and lookups).
        max_joint_speed: the robot's fastest joint speed [rad/s] (UR5: pi); joint states that would need a joint
            faster than that (by more than 25 %) are refused as corrupt.
        tactile_calibration: the pad's :class:`~torch_gpioius.sensors.tactile.TactileCalibration`; required with
            ``topics.tactile``.
        tactile_transform: ``T_tool_pad``, the pad frame in the fingertip's frame (the frame the forward kinematics
            gives at ``tool_offset``), in the same forms as ``camera_transform``; default identity (the gel centred
            on the fingertip centre, facing along the tool's z axis).
        patch: :class:`~torch_gpioius.exploration.patches.PatchThinning` (thinning and free-space margin).
        settings: the estimator's settings (:class:`~torch_gpioius.models.estimator.EstimatorSettings` or a preset's
            name, or changes to the "default" preset: an :class:`~torch_gpioius.models.overrides.EstimatorOverrides`),
            recorded in the dataset for ``fit``; their labels give the free space and the voxel (a voxel rule sized
            to ``crop``'s largest extent, else the labels' voxel); their inside points are placed behind the
            contacts along the measured forces (``touch_inside``; judged as an exploration judges them), none behind
            the seen surface (the recorded settings say so). None: the paper's 5 cm voxels and no settings recorded
            (``fit`` then uses the inverse multiquadric of 0.1 m and 0.006, or the deprecated ``kernel`` / ``noise``).
        camera_bound: the largest error the camera's pose in the base frame (its extrinsic calibration, or the tf
            that places it) may have, a :class:`~torch_gpioius.sensors.simulated.CameraError` or its text
            (``"6mm,1deg"``): the clouds, as one capture, are moved rigidly about the camera to agree with the
            contacts (along the measured forces) within that bound before they are labelled
            (:func:`~torch_gpioius.sensors.extrinsics.correct_captures`, as ``gpioius fit --camera-bound`` corrects a
            user's files); ``meta["camera_corrections"]`` records it and a correction beyond half the bound is warned
            of. For a camera fixed in the base frame (the paper's Kinect); one that rides on the arm needs
            ``camera_mount``. None: the clouds as the calibration places them.
        camera_mount: with ``camera_bound``, the tf frame of the link a camera rides on (a wrist camera's ``tool0``
            or ``flange``): its error is then its hand-eye transform's, one in that frame for every cloud, and the
            clouds taken from several of the link's poses (at most :data:`MOUNT_CAPTURES` of them, spread over the
            recording) correct it together; every cloud then moves by it as the link placed it. The record says
            ``mount_frame`` and the ``mount``'s correction. None: a camera fixed in the base frame (clouds whose pose
            changes between them are refused, naming this).
        **deprecated: ``policy`` (an :class:`~torch_gpioius.models.labels.ObservationPolicy` in place of the
            settings' labels), ``kernel`` and ``noise`` (stored in the header for the fit), for one release: give
            ``settings=EstimatorOverrides(policy=..., kernel=..., noise=...)``.

    With ``topics.tactile``, every pad frame stamped at a contact (the nearest wrench sample within ``max_gap``
    has ``|F| >= contact_force``) becomes a patch (:func:`~torch_gpioius.exploration.patches.patch_observations`)
    at the pad's pose from the joint states interpolated at its stamp; frames out of contact, or in contact but
    with no pixel pressed to the contact depth, are counted and skipped. Surface points of later frames are thinned
    against the earlier ones to the patch spacing, and the fingertip's free space is kept the policy's margin from
    them too.

    Why this many parameters: a recording's frames, thresholds and sensors are each one fact of the user's rig that
    the bag does not hold; the estimator's settings, the part that grows, are one object (``settings``).

    Clouds are read one at a time and averaged into the voxels as they come (:class:`torch_gpioius.geometry.voxels.
    VoxelAccumulator`), so memory holds one cloud and the occupied voxels, not the recording.

    Returns:
        The dataset: inner contacts (y 0) and free space (y 1) with steps 1..k in time order, outer observations
        at step 0; ``trace`` holds the fingertip ``positions``, ``forces`` [N] (sensor frame) and ``timestamps``
        [s] of every wrench sample; ``meta`` records the bag, topics, frames and thresholds.

    Raises:
        BagImportError: one line naming the topic and the cause (missing topic, wrong type, empty, a time gap,
            a backwards clock, an empty or all-NaN cloud, no x/y/z fields or repeated/overlapping ones, implausible
            coordinates, a joint named twice or moving faster than the robot can, a NaN or non-rotation tf, an
            unknown camera frame, a pad frame that is not a depth image or presses beyond the gel's reach).
        ValueError: bad arguments.
        TypeError: a keyword it does not take.
    """
    from ..models.overrides import loose_keywords, warn_loose

    loose = loose_keywords("import_bag", deprecated, ("policy", "kernel", "noise"))
    warn_loose("import_bag", 2, **loose)
    s = _BagImport.checked(bag, topics=topics, base_frame=base_frame, camera_transform=camera_transform,
                           tool_offset=tool_offset, tip_radius=tip_radius, contact_force=contact_force,
                           contact_spacing=contact_spacing, max_gap=max_gap, joint_names=joint_names, **loose,
                           crop=crop, time_window=time_window,
                           max_joint_speed=max_joint_speed, tactile_calibration=tactile_calibration,
                           tactile_transform=tactile_transform, patch=patch, settings=settings,
                           camera_bound=camera_bound, camera_mount=camera_mount)
    reader = _open(s.path)
    try:
        if not list(reader.connections):
            raise BagImportError(f"{s.path}: the bag has no topics")
        wrenches = _messages(reader, s.path, s.topics.wrench, "wrench")
        joint_msgs = _messages(reader, s.path, s.topics.joints, "joints")
        _connections(reader, s.path, s.topics.cloud, "cloud")       # present and typed, before any work
        tf = None if s.T_fixed is not None else _read_tf(reader, s)
        inner = _inner_from_wrenches(s, wrenches, joint_msgs)
        pads = _pads(reader, s, inner)
        outer = _outer_from_clouds(reader, s, tf, inner["t_first"], _camera_correction(reader, s, tf, inner))
    finally:
        reader.close()
    return _bag_dataset(s, inner, pads, outer)


@dataclass(frozen=True)
class _BagImport:
    """:func:`import_bag`'s settings, checked once before the bag is opened (fields as its arguments; ``window`` is
    ``(start, end)`` [s] after the first wrench sample or None, ``T_fixed`` the camera transform or None, ``ur5``
    the kinematics with the tool offset)."""

    path: Path
    topics: BagTopics
    base: str
    T_fixed: np.ndarray | None
    tool_offset: tuple
    tip_radius: float
    contact_force: float
    contact_spacing: float
    max_gap: float
    names: tuple
    policy: object
    crop: np.ndarray | None
    kernel: dict | None                 # the kernel's description (it carries its length scale)
    noise: float | None
    window: tuple | None
    max_joint_speed: float
    calibration: object
    T_pad: np.ndarray | None
    patch: object
    ur5: object
    estimator: object = None
    camera_bound: object = None          # a CameraError, or None
    camera_mount: str | None = None      # the tf frame a camera rides on, or None (fixed in the base frame)

    @classmethod
    def checked(cls, bag, *, topics, base_frame, camera_transform, tool_offset, tip_radius, contact_force,
                contact_spacing, max_gap, joint_names, policy, crop, kernel, noise, time_window, max_joint_speed,
                tactile_calibration, tactile_transform, patch, settings=None, camera_bound=None,
                camera_mount=None) -> "_BagImport":
        from kinematics.dh import UR5_JOINT_NAMES
        from kinematics.ur5 import UR5

        from ..exploration.observations import ObservationPolicy

        from ..kernels import as_kernel

        topics = topics or BagTopics()
        if kernel is not None:
            try:
                kernel = as_kernel(kernel).describe()
            except TypeError as exc:
                raise ValueError(f"import_bag: {exc}") from None
        estimator = _bag_settings(settings, crop, policy)
        policy = policy or (estimator.labels if estimator is not None else ObservationPolicy(voxel=0.05))
        names = tuple(joint_names or UR5_JOINT_NAMES)
        for name, value, lo, hi in (("contact_force", contact_force, 1e-3, 1e3),
                                    ("contact_spacing", contact_spacing, 0, 1.0), ("max_gap", max_gap, 1e-4, 60.0),
                                    ("tip_radius", tip_radius, 0, 0.1)):
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not (math.isfinite(value) and
                                                                                      lo <= value <= hi):
                raise ValueError(f"import_bag: {name} must be in [{lo:g}, {hi:g}], got {value!r}")
        if len(names) != 6:
            raise ValueError(f"import_bag: joint_names needs the 6 UR5 joints, got {len(names)}")
        T_fixed = parse_transform(camera_transform) if camera_transform is not None else None
        T_pad = None
        if topics.tactile is not None:
            from ..exploration.patches import PatchThinning
            from ..sensors.tactile import TactileCalibration

            if not isinstance(tactile_calibration, TactileCalibration):
                raise ValueError("import_bag: topics.tactile needs tactile_calibration (a TactileCalibration: pixel "
                                 f"pitch, gel thickness, contact depth), got {tactile_calibration!r}")
            T_pad = np.eye(4) if tactile_transform is None else parse_transform(tactile_transform)
            patch = patch or PatchThinning()
            if not isinstance(patch, PatchThinning):
                raise ValueError(f"import_bag: patch must be a PatchThinning, got {type(patch).__name__}")
        if crop is not None:
            crop = as_bounds(crop, 3)
        window = None
        if time_window is not None:
            try:
                w0, w1 = (float(v) for v in time_window)
            except (TypeError, ValueError):
                raise ValueError(f"import_bag: time_window must be (start, end) in seconds, got {time_window!r}") \
                    from None
            if not (math.isfinite(w0) and math.isfinite(w1) and 0 <= w0 < w1):
                raise ValueError(f"import_bag: time_window must satisfy 0 <= start < end (finite seconds), got "
                                 f"{time_window!r}")
            window = (w0, w1)
        if camera_bound is not None:
            from ..sensors.simulated.camera import CameraError

            try:
                camera_bound = CameraError.parse(camera_bound).check_bound()
            except ValueError as exc:
                raise ValueError(f"import_bag: {exc}") from None
        if camera_mount is not None:
            if not isinstance(camera_mount, str) or not camera_mount.strip("/ "):
                raise ValueError(f"import_bag: camera_mount must name a tf frame, got {camera_mount!r}")
            if camera_bound is None:
                raise ValueError("import_bag: camera_mount names the link whose camera camera_bound corrects; give "
                                 "camera_bound too")
            if T_fixed is not None:
                raise ValueError("import_bag: camera_mount takes the camera's poses from tf (the link's, then the "
                                 "camera's on it); camera_transform fixes one pose in the base frame: give one")
            camera_mount = camera_mount.strip("/ ")
        return cls(Path(bag), topics, base_frame.lstrip("/"), T_fixed, tuple(tool_offset), tip_radius, contact_force,
                   contact_spacing, max_gap, names, policy, crop, kernel, noise, window, max_joint_speed,
                   tactile_calibration, T_pad, patch, UR5(tool_offset=tool_offset), estimator, camera_bound,
                   camera_mount)

    def in_window(self, t: float, t_first: float) -> bool:
        return self.window is None or t_first + self.window[0] <= t <= t_first + self.window[1]


def _read_tf(reader, s: _BagImport):
    """Every transform of the tf topics, checked (finite, a rotation), into a buffer for lookups."""
    tf = _TfBuffer()
    for tf_topic in s.topics.tf:
        for t, msg in _messages(reader, s.path, tf_topic, "tf", required=False):
            for ts in msg.transforms:
                tr, rot = ts.transform.translation, ts.transform.rotation
                stamp = _stamp(ts, int(t * 1e9))
                where = (f"{s.path}: topic {tf_topic}: the transform {ts.header.frame_id} -> "
                         f"{ts.child_frame_id} at t = {stamp:.6f} s")
                try:
                    if not all(math.isfinite(v) for v in (tr.x, tr.y, tr.z)):
                        raise ValueError(f"translation {(tr.x, tr.y, tr.z)} is not finite")
                    T_link = _homogeneous((tr.x, tr.y, tr.z), (rot.x, rot.y, rot.z, rot.w))
                except ValueError as exc:
                    raise BagImportError(f"{where}: {exc}") from None
                tf.add(ts.header.frame_id, ts.child_frame_id, stamp, T_link, static="static" in tf_topic)
    return tf


def _inner_from_wrenches(s: _BagImport, wrenches: list, joint_msgs: list) -> dict:
    """The fingertip at every wrench sample (joint states interpolated, forward kinematics): contacts where
    ``|F| >= contact_force`` (thinned), free space elsewhere, each with its step."""
    from ..exploration.observations import thin_indices

    path, topics = s.path, s.topics
    t_w = np.array([t for t, _ in wrenches])
    t_first = float(t_w[0])
    if s.window is not None:
        inside = np.array([s.in_window(t, t_first) for t in t_w])
        if not inside.any():
            raise BagImportError(f"{path}: topic {topics.wrench}: no sample in the time window "
                                 f"{_window_text(*s.window)} after the first one (the topic spans "
                                 f"{t_w[-1] - t_first:.3f} s)")
        wrenches = [w for w, keep in zip(wrenches, inside) if keep]
        t_w = t_w[inside]
    forces = np.array([[m.wrench.force.x, m.wrench.force.y, m.wrench.force.z] for _, m in wrenches],
                      dtype=np.float64)
    if not np.isfinite(forces).all():
        k = int(np.flatnonzero(~np.isfinite(forces).all(axis=1))[0])
        raise BagImportError(f"{path}: topic {topics.wrench}: the force at t = {t_w[k]:.6f} s is NaN or inf")
    t_j, q_j = _joint_table(path, topics.joints, joint_msgs, s.names, s.max_joint_speed)
    q = _interpolate(path, topics.joints, t_j, q_j, t_w, s.max_gap)
    with torch.no_grad():
        T = s.ur5.forward_kinematics(torch.as_tensor(q)).numpy()
    tips = T[:, :3, 3]
    magnitude = np.linalg.norm(forces, axis=1)
    touching = magnitude >= s.contact_force
    if not touching.any():
        raise BagImportError(f"{path}: topic {topics.wrench}: no sample reaches |F| >= {s.contact_force:g} N "
                             f"(largest {magnitude.max():.3g} N): no contact to learn the inner shape from")
    # the measured force in the base frame: the surface pushes the fingertip out along its outward normal
    direction = np.einsum("nij,nj->ni", T[:, :3, :3], forces) / np.maximum(magnitude, 1e-12)[:, None]
    contact_pts = tips - s.tip_radius * direction if s.tip_radius > 0 else tips.copy()
    idx_c = np.flatnonzero(touching)
    keep_c = idx_c[thin_indices(contact_pts[idx_c], s.contact_spacing, np.empty((0, 3)), 0.0)] \
        if s.contact_spacing > 0 else idx_c
    contacts = contact_pts[keep_c]
    # step of each sample: 1 + the number of kept contacts strictly before it (free space arrives with the next
    # contact, as in the exploration); contacts get 1..k
    order = np.searchsorted(keep_c, np.arange(len(t_w)), side="left")
    step_of = np.minimum(order + 1, len(keep_c))
    free_idx = np.flatnonzero(~touching)
    keep_f = free_idx[thin_indices(tips[free_idx], s.policy.free_space_spacing, contacts,
                                   s.policy.free_space_margin)]
    return {"t_w": t_w, "t_first": t_first, "forces": forces, "tips": tips, "touching": touching,
            "step_of": step_of, "t_j": t_j, "q_j": q_j, "contacts": contacts, "normals": direction[keep_c],
            "free": tips[keep_f],
            "free_steps": step_of[keep_f], "n_wrench": len(wrenches), "n_joints": len(joint_msgs)}


def _pads(reader, s: _BagImport, inner: dict) -> dict:
    """The gel pad's frames at contacts, as patches (``topics.tactile``); the fingertip's free space is then kept
    the policy's margin from their surface points (``inner`` is updated)."""
    pads = {"surface": [], "free": [], "surface_steps": [], "free_steps": [], "counts": (0, 0, 0, 0)}
    if s.topics.tactile is None:
        return pads
    window = None if s.window is None else (inner["t_first"] + s.window[0], inner["t_first"] + s.window[1])
    pads["counts"] = _import_pads(reader, s.path, s.topics, inner["t_w"], inner["touching"], inner["step_of"],
                                  inner["t_j"], inner["q_j"], s.max_gap, s.ur5, s.T_pad, s.calibration, s.patch,
                                  window, pads)
    if pads["surface"]:
        far = _far_from(inner["free"], np.concatenate(pads["surface"]), s.policy.free_space_margin)
        inner["free"], inner["free_steps"] = inner["free"][far], inner["free_steps"][far]
    return pads


def _camera_pose(s: _BagImport, tf, frame: str, t: float) -> np.ndarray:
    """``T_base_cloudframe`` `(4, 4)` of a cloud stamped ``t`` in ``frame``: the given transform, else tf's."""
    if s.T_fixed is not None:
        return s.T_fixed
    try:
        return tf.lookup(s.base, frame, t)
    except LookupError as exc:
        raise BagImportError(f"{s.path}: topic {s.topics.cloud}: {exc}; pass camera_transform / "
                             "--camera-transform") from None


def _clouds(reader, s: _BagImport, tf, t_first: float):
    """Each cloud stamped in the time window, into the base frame, one at a time: ``(t, msg, frame, T_bc, points)``
    with ``points`` `(n, 3)` its finite points [m] in the base frame and ``T_bc`` its frame's pose
    (:func:`_camera_pose`); an empty cloud comes as `(0, 3)` points and no pose (none is looked up for it)."""
    for t, msg in _iter_messages(reader, s.path, s.topics.cloud, "cloud"):
        if not s.in_window(t, t_first):
            continue
        pts = decode_point_cloud2(msg, topic=s.topics.cloud)
        frame = msg.header.frame_id.lstrip("/")
        if not len(pts):
            yield t, msg, frame, None, np.zeros((0, 3))
            continue
        T_bc = _camera_pose(s, tf, frame, t)
        pts_b = pts @ T_bc[:3, :3].T + T_bc[:3, 3]
        del pts                             # one cloud held at a time, not its two frames' copies
        yield t, msg, frame, T_bc, pts_b


#: The voxel [m] the clouds are averaged into before their capture is corrected (:func:`_camera_correction`).
CORRECTION_VOXEL = 0.005
#: A camera on a moving link: at most this many of its clouds, spread over the recording, fit its one correction (each
#: is a capture; their overlaps are compared pairwise), which then moves every cloud.
MOUNT_CAPTURES = 12


def _mount_pose(s: _BagImport, tf, t: float, where: str) -> np.ndarray:
    """``T_base_mount`` `(4, 4)` at ``t`` from tf (``s.camera_mount``'s frame)."""
    try:
        return tf.lookup(s.base, s.camera_mount, t)
    except LookupError as exc:
        raise BagImportError(f"{s.path}: {where}: camera_mount: {exc}") from None


def _camera_correction(reader, s: _BagImport, tf, inner: dict):
    """With ``s.camera_bound``: the clouds' measured points in the crop box, voxel-averaged, corrected from the
    contacts along their measured forces (:func:`~torch_gpioius.sensors.extrinsics.correct_captures`): as one capture
    of a camera fixed in the base frame, or, with ``s.camera_mount``, as captures of one camera riding on that link
    from its poses then (one correction in the link's frame). The
    :class:`~torch_gpioius.sensors.extrinsics.CaptureCorrections` (a large correction warned of), None without a
    bound. A first pass over the clouds; :func:`_outer_from_clouds` labels them moved.

    Raises:
        BagImportError: a camera whose pose changes between clouds without a mount (it moves with the arm), one that
            moves on its mount, a mount tf cannot place, or no point in the box.
    """
    if s.camera_bound is None:
        return None
    import warnings

    from ..geometry.voxels import VoxelAccumulator, voxel_average
    from ..sensors.extrinsics import correct_captures
    from ..sensors.pointcloud import PointCloud

    # 5 mm voxels: the surface as measured (the labels' coarser voxels average a curved cover onto its chords, and
    # the gap the contacts show would read short), within the memory of a few clouds
    acc, pose, on_mount, captures, mounts = VoxelAccumulator(CORRECTION_VOXEL), None, None, [], []
    where = f"topic {s.topics.cloud}"
    for t, _, frame, T_bc, pts in _clouds(reader, s, tf, inner["t_first"]):
        if T_bc is None:                    # an empty cloud
            continue
        if s.crop is not None:
            pts = pts[np.all((pts >= s.crop[0]) & (pts <= s.crop[1]), axis=1)]
        if s.camera_mount is not None:      # each cloud a capture, from the link's pose then
            T_bm = _mount_pose(s, tf, t, where)
            T_mc = np.linalg.inv(T_bm) @ T_bc
            if on_mount is None:
                on_mount = T_mc
            elif not np.allclose(T_mc, on_mount, atol=1e-6):
                raise BagImportError(f"{s.path}: {where}: camera_mount: the clouds' frame ({frame} at t = {t:.3f} s) "
                                     f"moves on {s.camera_mount} (a camera rides rigidly on its mount); name the "
                                     "link it is fixed to")
            seen = voxel_average(pts, CORRECTION_VOXEL)
            if len(seen) >= 10:
                captures.append(PointCloud(seen, T_bc[:3, 3]))
                mounts.append(T_bm)
            continue
        if pose is None:
            pose = T_bc
        elif not np.allclose(T_bc, pose, atol=1e-6):
            raise BagImportError(f"{s.path}: {where}: camera_bound corrects one camera fixed in the base frame; the "
                                 f"pose of the clouds' frame ({frame} at t = {t:.3f} s) changes between clouds (a "
                                 "camera riding on the arm: give camera_mount, the link it rides on; or several "
                                 "cameras): or import without camera_bound")
        if len(pts):
            acc.add(pts)
    bound = dict(max_translation=s.camera_bound.translation, max_rotation=s.camera_bound.rotation)
    if s.camera_mount is not None:
        if not captures:
            raise BagImportError(f"{s.path}: {where}: camera_bound: no cloud point to correct")
        pick = np.unique(np.linspace(0, len(captures) - 1, min(len(captures), MOUNT_CAPTURES)).round().astype(int))
        found = correct_captures([captures[i] for i in pick], inner["contacts"], inner["normals"], **bound,
                                 mount=[mounts[i] for i in pick])
        names = [f"the camera on {s.camera_mount}"]
    else:
        seen = acc.mean()
        if pose is None or not len(seen):
            raise BagImportError(f"{s.path}: {where}: camera_bound: no cloud point to correct")
        found = correct_captures([PointCloud(seen, pose[:3, 3])], inner["contacts"], inner["normals"], **bound)
        names = [s.topics.cloud]
    for line in found.warnings(names):
        warnings.warn(line, UserWarning, stacklevel=4)
    return found


def _outer_from_clouds(reader, s: _BagImport, tf, t_first: float, corrections=None) -> dict:
    """One cloud at a time into the base frame (moved by ``corrections``, :func:`_camera_correction`, where given),
    the exploration's vision rule (surface and free space along the rays), then the voxels; memory holds one cloud
    and the occupied voxels."""
    from ..exploration.observations import ObservationPolicy, vision_observations
    from ..sensors.pointcloud import PointCloud
    from ..geometry.voxels import VoxelAccumulator

    path, topics, policy = s.path, s.topics, s.policy
    cloud_frames = set()
    n_clouds = n_raw = n_declared = n_used = 0
    no_voxel = ObservationPolicy(vision_free_offset=policy.vision_free_offset, voxel=None,
                                 free_space_spacing=policy.free_space_spacing,
                                 free_space_margin=policy.free_space_margin,
                                 vision_free_far=policy.vision_free_far,
                                 ray_smoothing=None if policy.voxel else policy.ray_smoothing)
    if policy.voxel:
        seen_acc, free_acc = VoxelAccumulator(policy.voxel), VoxelAccumulator(policy.voxel)
    else:
        seen_all, free_all = [], []
    for t, msg, frame, T_bc, pts_b in _clouds(reader, s, tf, t_first):
        n_clouds += 1
        n_declared += int(msg.height) * int(msg.width)
        n_raw += len(pts_b)
        if len(pts_b) == 0:
            continue
        cloud_frames.add(frame)
        if corrections is not None:         # the capture moved about its camera, and the camera with it
            fix = corrections.captures[0] if corrections.mount is None else \
                corrections.mount.through(_mount_pose(s, tf, t, f"topic {topics.cloud}"))
            pts_b = fix.apply(pts_b)
            T_bc = T_bc.copy()
            T_bc[:3, 3] = fix.apply(T_bc[None, :3, 3])[0]
        try:
            x, y = vision_observations(PointCloud(pts_b, origin=T_bc[:3, 3]), no_voxel, s.crop)
        except ValueError:
            continue  # nothing of this cloud inside the crop box
        n_used += 1
        if policy.voxel:
            # this frame's measured points in the crop box, each in the voxel its depth smoothed along the rays
            # lies in (ray_smoothing), as an exploration averages each capture
            measured = x[y == 0]
            at = (PointCloud(measured, origin=T_bc[:3, 3]).smoothed_along_rays(policy.ray_smoothing).points
                  if policy.ray_smoothing else None)
            seen_acc.add(measured, at=at)
            free_acc.add(x[y == 1])
        else:
            seen_all.append(x[y == 0])
            free_all.append(x[y == 1])
    window = "" if s.window is None else f" in the time window {_window_text(*s.window)}"
    if n_clouds == 0:
        raise BagImportError(f"{path}: topic {topics.cloud}: no cloud{window}")
    if n_declared == 0:
        raise BagImportError(f"{path}: topic {topics.cloud}: every cloud{window} is empty (0 points declared)")
    if n_raw == 0:
        raise BagImportError(f"{path}: topic {topics.cloud}: every point of every cloud{window} is NaN or inf "
                             f"({n_declared} points, no depth)")
    if not n_used:
        raise BagImportError(f"{path}: topic {topics.cloud}: no cloud point lies inside the crop box "
                             f"{s.crop.tolist()}")
    if policy.voxel:
        seen, free_o = seen_acc.mean(), free_acc.mean()
    else:
        seen = np.concatenate(seen_all)
        free_o = np.concatenate(free_all) if free_all else np.empty((0, 3))
    return {"seen": seen, "free": free_o, "frames": sorted(cloud_frames), "n_clouds": n_clouds, "n_raw": n_raw,
            "corrections": corrections}


def _bag_settings(settings, crop, policy):
    """The estimator settings a bag import records (None without ``settings``): the voxel rule sized to ``crop``,
    ``policy`` in place of the labels where given, and no inside points behind the seen surface (a bag's clouds
    are averaged over a moving camera's poses, which leaves a seen point no single viewpoint to orient its normal
    by); those behind the contacts are placed, along the measured forces."""
    if settings is None:
        return None
    from ..models.estimator import EstimatorSettings
    from ..models.overrides import EstimatorOverrides

    try:
        if isinstance(settings, EstimatorOverrides):       # changes to the default preset
            est = settings.apply(EstimatorSettings.of("default"))
        else:
            est = EstimatorSettings.of(settings)
    except ValueError as exc:
        raise ValueError(f"import_bag: {exc}") from None
    if crop is not None and est.sized_to_object:
        box = np.asarray(crop, dtype=np.float64)
        est = est.for_extent(float(np.max(box[1] - box[0])))
    if policy is not None:
        est = est.replace(labels=policy, voxel_rule=None)
    if est.labels.vision_inside:
        est = est.replace(labels={"vision_inside": None, "vision_inside_gap": None})
    return est


def _inside_points(s: _BagImport, inner: dict, seen: np.ndarray, free_o: np.ndarray):
    """The inside points behind the contacts (the settings' ``touch_inside`` along each measured force), each
    judged as an exploration judges it (:func:`~torch_gpioius.exploration.observations.inside_checked_by_step`):
    `(k, 3)` points, `(k,)` labels and `(k,)` steps; none without settings that place them."""
    from ..exploration.observations import inside_checked_by_step

    labels = s.estimator.labels if s.estimator is not None else None
    if labels is None or labels.touch_inside is None:
        return np.empty((0, 3)), np.empty(0), np.empty(0, np.int64)
    contacts = inner["contacts"]
    points, y_in, of = labels.behind_contacts(contacts, inner["normals"])
    steps_in = of + 1                                          # contact j is step j + 1
    x = np.concatenate([contacts, inner["free"], points])
    y = np.r_[np.zeros(len(contacts)), np.ones(len(inner["free"])), y_in]
    steps = np.r_[np.arange(1, len(contacts) + 1), inner["free_steps"], steps_in]
    x, y, keep = inside_checked_by_step(x, y, steps, labels, np.concatenate([seen, free_o]).reshape(-1, 3),
                                        np.r_[np.zeros(len(seen)), np.ones(len(free_o))])
    ours = slice(len(contacts) + len(inner["free"]), None)        # inside_halvings: some moved up their line
    points, y_in, keep = x[ours], y[ours], keep[ours]
    return points[keep], y_in[keep], steps_in[keep]


def _bag_dataset(s: _BagImport, inner: dict, pads: dict, outer: dict) -> Dataset:
    """The imported observations as a :class:`Dataset`, with the bag's topics, frames, thresholds and counts."""
    contacts, free, free_steps = inner["contacts"], inner["free"], inner["free_steps"]
    seen, free_o = outer["seen"], outer["free"]
    behind, behind_y, behind_steps = _inside_points(s, inner, seen, free_o)
    repeats = s.estimator.labels.contact_repeats if s.estimator is not None else 1
    steps_c = np.repeat(np.arange(1, len(contacts) + 1), repeats)  # each contact k times: its noise sigma^2 / k
    contacts = np.repeat(contacts, repeats, axis=0)
    p_surf = np.concatenate(pads["surface"]) if pads["surface"] else np.empty((0, 3))
    p_free = np.concatenate(pads["free"]) if pads["free"] else np.empty((0, 3))
    x = np.concatenate([contacts, p_surf, free, p_free, behind, seen, free_o])
    y = np.concatenate([np.zeros(len(contacts) + len(p_surf)), np.ones(len(free) + len(p_free)), behind_y,
                        np.zeros(len(seen)), np.ones(len(free_o))])
    n_inner = len(contacts) + len(p_surf) + len(free) + len(p_free) + len(behind)
    task = np.concatenate([np.zeros(n_inner), np.ones(len(seen) + len(free_o))]).astype(np.int64)
    step = np.concatenate([steps_c, *pads["surface_steps"], np.asarray(free_steps),
                           *pads["free_steps"], behind_steps, np.zeros(len(seen) + len(free_o))]).astype(np.int64)
    topics = s.topics
    meta = {"source": f"rosbag:{s.path.name}", "frame": s.base, "bag_topics": {"cloud": topics.cloud,
            "wrench": topics.wrench, "joints": topics.joints}, "camera_frames": outer["frames"],
            "contact_force": s.contact_force, "contact_spacing": s.contact_spacing, "tip_radius": s.tip_radius,
            "tool_offset": [float(v) for v in s.tool_offset], "voxel_size": s.policy.voxel,
            "time_window": None if s.window is None else list(s.window),
            "counts": {"wrench": inner["n_wrench"], "joint_states": inner["n_joints"], "clouds": outer["n_clouds"],
                       "cloud_points": int(outer["n_raw"]), "contacts": int(len(inner["contacts"])),
                       "free_space": int(len(free)), "outer_surface": int(len(seen)),
                       "outer_free_space": int(len(free_o)), "inside_points": int(len(behind))}}
    if topics.tactile is not None:
        n_pad, n_pad_used, n_pad_off, n_pad_empty = pads["counts"]
        meta["bag_topics"]["tactile"] = topics.tactile
        meta["tactile"] = {"calibration": dataclasses.asdict(s.calibration), "T_tool_pad": s.T_pad.tolist(),
                           "patch": dataclasses.asdict(s.patch)}
        meta["counts"].update({"pad_frames": n_pad, "pad_frames_used": n_pad_used,
                               "pad_frames_out_of_contact": n_pad_off, "pad_frames_untouched": n_pad_empty,
                               "patch_surface": int(len(p_surf)), "patch_free_space": int(len(p_free))})
    if s.kernel is not None:
        meta["kernel"] = s.kernel
    if s.noise is not None:
        meta["noise"] = s.noise
    if s.estimator is not None:
        meta["estimator"] = s.estimator.to_dict()
    if outer["corrections"] is not None:
        meta["camera_corrections"] = outer["corrections"].as_record()
        if s.camera_mount is not None:
            meta["camera_corrections"]["mount_frame"] = s.camera_mount
    trace = {"positions": inner["tips"], "forces": inner["forces"], "timestamps": inner["t_w"] - inner["t_w"][0]}
    return Dataset(x, y, task, step, meta=meta, trace=trace)


def _import_pads(reader, path: Path, topics: BagTopics, t_w: np.ndarray, touching: np.ndarray, step_of: np.ndarray,
                 t_j: np.ndarray, q_j: np.ndarray, max_gap: float, ur5, T_pad: np.ndarray, calibration, settings,
                 window, out: dict) -> tuple[int, int, int, int]:
    """The pad frames of ``topics.tactile`` as patches into ``out`` (see :func:`import_bag`); returns the frames
    read, used, out of contact and untouched."""
    from ..exploration.patches import patch_observations
    from ..sensors.tactile import TactileReading, depth_from_image_message

    n = used = off = empty = 0
    kept = np.empty((0, 3))
    for t, msg in _iter_messages(reader, path, topics.tactile, "tactile"):
        if window and not window[0] <= t <= window[1]:
            continue
        n += 1
        k = int(np.clip(np.searchsorted(t_w, t), 1, len(t_w) - 1))
        k = k if abs(t_w[k] - t) < abs(t_w[k - 1] - t) else k - 1
        if abs(t_w[k] - t) > max_gap or not touching[k]:
            off += 1
            continue
        where = f"{path}: topic {topics.tactile}: the frame at t = {t:.6f} s"
        try:
            depth = depth_from_image_message(msg)
        except ValueError as exc:
            raise BagImportError(f"{where}: {exc}") from None
        q = _interpolate(path, topics.joints, t_j, q_j, np.array([t]), max_gap)
        with torch.no_grad():
            T_tool = ur5.forward_kinematics(torch.as_tensor(q)).numpy()[0]
        try:
            reading = TactileReading(depth, T_tool @ T_pad, calibration, float(t))
        except ValueError as exc:
            raise BagImportError(f"{where}: {exc}") from None
        if not reading.contact_mask.any():
            empty += 1
            continue
        obs = patch_observations(reading, settings, int(step_of[k]))
        surf, free = obs.x[obs.y == 0], obs.x[obs.y == 1]
        surf = surf[_far_from(surf, kept, settings.spacing)]   # already thinned within the patch; now across frames
        kept = np.concatenate([kept, surf])
        used += 1
        out["surface"].append(surf)
        out["surface_steps"].append(np.full(len(surf), int(step_of[k])))
        out["free"].append(free)
        out["free_steps"].append(np.full(len(free), int(step_of[k])))
    if out["free"]:                  # the free space of every patch kept its margin from every patch's surface
        allf = np.concatenate(out["free"])
        steps = np.concatenate(out["free_steps"])
        far = _far_from(allf, kept, settings.free_margin)
        out["free"], out["free_steps"] = [allf[far]], [steps[far]]
    return n, used, off, empty


def _far_from(points: np.ndarray, avoid: np.ndarray, margin: float) -> np.ndarray:
    """`(n,)` bool: points at least ``margin`` from every point of ``avoid`` (a k-d tree: a recording's patches hold
    thousands of points, too many for a dense distance matrix against its free space)."""
    from scipy.spatial import cKDTree

    if not len(points) or not len(avoid):
        return np.ones(len(points), bool)
    d, _ = cKDTree(avoid).query(points, k=1)
    return d >= margin

# ----------------------------------------------------------------------------------------------- writing
@dataclass
class BagMessage:
    """One message to write: ``topic``, ROS ``msgtype`` (e.g. ``sensor_msgs/msg/JointState``), receive time
    ``t_ns`` [ns] and the ``rosbags`` message object."""

    topic: str
    msgtype: str
    t_ns: int
    msg: object


def write_bag(path: str | os.PathLike, messages: Sequence[BagMessage], *, storage: str = "mcap") -> Path:
    """Write messages into a new ROS 2 bag with ``rosbags``' writer (``storage`` ``"mcap"`` or ``"sqlite3"``).

    Messages are written in time order. Returns the bag's folder. Refuses to overwrite an existing path.
    """
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    plugins = {"mcap": StoragePlugin.MCAP, "sqlite3": StoragePlugin.SQLITE3}
    if storage not in plugins:
        raise ValueError(f"write_bag: storage must be one of {sorted(plugins)}, got {storage!r}")
    path = Path(path)
    if path.exists():
        raise FileExistsError(f"write_bag: {path} exists")
    typestore = get_typestore(Stores.ROS2_HUMBLE)
    with Writer(path, version=9, storage_plugin=plugins[storage]) as writer:
        conns: dict[tuple[str, str], object] = {}
        for m in sorted(messages, key=lambda m: m.t_ns):
            key = (m.topic, m.msgtype)
            if key not in conns:
                conns[key] = writer.add_connection(m.topic, m.msgtype, typestore=typestore)
            writer.write(conns[key], int(m.t_ns), typestore.serialize_cdr(m.msg, m.msgtype))
    return path
