"""A synthetic ROS 2 recording of a UR5 touching a sphere under a spherical cover: the bag the tests, the rosbag
tutorial and the README use, and a template of what :func:`torch_gpioius.io.rosbag.import_bag` expects.

Needs the ``rosbag`` extra (``rosbags``).
"""

from __future__ import annotations

import math

import numpy as np
import torch

from ..io.rosbag import BagMessage
from ..sensors.pointcloud import look_at

__all__ = ["example_bag_messages"]


def example_bag_messages(*, center=(-0.55, -0.109, 0.0), radius: float = 0.08, cover_radius: float = 0.1,
                         tip_radius: float = 0.005, tool_offset=(0.0, 0.0, 0.05), speed: float = 0.08,
                         joint_rate: float = 25.0, wrench_rate: float = 100.0, press_force: float = 2.5,
                         image=(36, 48), seed: int = 0, camera: str = "fixed") -> tuple[list[BagMessage], dict]:
    """A synthetic recording of a UR5 touching a sphere under a spherical cover, as ROS 2 messages.

    The fingertip (a ball of ``tip_radius`` at ``tool_offset`` from the flange) approaches the sphere from above,
    slides along two arcs on it pressing with ``press_force``, lifts and re-presses; the joints (UR driver names)
    come from :meth:`kinematics.UR5.cartesian_step` along that path. A depth camera whose optical frame hangs off
    ``base -> camera_link -> camera_depth_optical_frame`` in ``/tf_static`` sees the cover (an organised cloud with
    NaN where rays miss, an ``rgb`` field and row padding). With ``camera="wrist"`` the camera rides on the flange
    instead (``tool0 -> camera_link -> camera_depth_optical_frame`` in ``/tf_static``, the flange's pose in ``/tf`` at
    every joint state) and takes :data:`WRIST_CLOUDS` clouds while the fingertip presses, each from the flange's pose
    then. Used by the tests, the rosbag tutorial and as a template for what :func:`import_bag` expects.

    Why this many parameters: each is one property of the synthetic recording (the body, the cover, the fingertip, the
    rates, the force, the image, where the camera is) that a test of the importer varies alone; all keywords with
    defaults.

    Returns:
        ``(messages, truth)``; ``truth`` has ``center`` `(3,)`, ``radius``, ``cover_radius``, ``tip_radius``,
        ``tool_offset``, ``T_base_optical`` `(4, 4)` (None for a wrist camera; then ``T_tool0_optical``) and
        ``contact_path`` `(k, 3)` (true contact points) [m].
    """
    if camera not in ("fixed", "wrist"):
        raise ValueError(f"example_bag_messages: camera must be 'fixed' or 'wrist', got {camera!r}")
    from kinematics.dh import UR5_JOINT_NAMES
    from kinematics.ur5 import UR5
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS2_HUMBLE).types
    rng = np.random.default_rng(seed)
    c = np.asarray(center, dtype=np.float64)
    ur5 = UR5(tool_offset=tool_offset)
    q = torch.tensor([0.0, -1.2, 1.5, -1.9, -1.57, 0.0], dtype=torch.float64)
    path, pressing = _fingertip_path(ur5.position(q).numpy(), c, radius + tip_radius, speed / joint_rate)
    # all path points at once: batched resolved-rate steps from the home pose until every one is reached
    qs = q.expand(len(path), 6).clone()
    target = torch.as_tensor(path)
    for _ in range(100):
        err = target - ur5.position(qs)
        if float(err.norm(dim=1).max()) < 1e-10:
            break
        qs = ur5.cartesian_step(qs, err)
    reached = ur5.position(qs).detach().numpy()
    R = ur5.forward_kinematics(qs).detach().numpy()[:, :3, :3]
    t0 = 1_700_000_000.0
    msgs, contact_path = _robot_messages(ts, t0, qs.detach().numpy(), reached, R, pressing, c, tip_radius,
                                         press_force, joint_rate, wrench_rate, rng, list(UR5_JOINT_NAMES))
    if camera == "fixed":
        T_bo = look_at(c + np.array([0.5, 0.3, 0.35]), c)
        msgs += _camera_messages(ts, t0, T_bo, c, cover_radius, image)
    else:
        flange = ur5.forward_kinematics(qs, frame="flange").detach().numpy()
        msgs += _wrist_camera_messages(ts, t0, flange, np.arange(len(qs)) / joint_rate, pressing, c, cover_radius,
                                       image)
        T_bo = None
    truth = {"center": c, "radius": radius, "cover_radius": cover_radius, "tip_radius": tip_radius,
             "tool_offset": tuple(tool_offset), "T_base_optical": T_bo, "contact_path": np.asarray(contact_path),
             "path_error": float(np.abs(reached - path).max()),
             **({"T_tool0_optical": WRIST_CAMERA} if camera == "wrist" else {})}
    return msgs, truth


def _fingertip_path(start: np.ndarray, c: np.ndarray, r_tip: float, spacing: float) -> tuple[np.ndarray, np.ndarray]:
    """The fingertip centre's path `(k, 3)` [m], a point every ``spacing``, and whether it presses at each `(k,)`:
    down from ``start`` onto the top of the sphere of radius ``r_tip`` about ``c``, along two arcs on it, lifting
    and re-pressing between them."""

    def arc(a0, a1, axis):  # points on the sphere of radius r_tip, angles from +z towards axis
        n = max(2, int(abs(a1 - a0) * r_tip / spacing))
        a = np.linspace(a0, a1, n)
        d = np.outer(np.cos(a), [0, 0, 1.0]) + np.outer(np.sin(a), axis)
        return c + r_tip * d

    def line(p0, p1):
        n = max(2, int(np.linalg.norm(p1 - p0) / spacing))
        return p0 + np.outer(np.linspace(0, 1, n), p1 - p0)

    top = c + [0, 0, r_tip]
    segs = [(line(start, top + [0, 0, 0.08]), False), (line(top + [0, 0, 0.08], top), False),
            (arc(0.0, 0.7, np.array([1.0, 0, 0])), True)]
    end = segs[-1][0][-1]
    out = c + (end - c) * (r_tip + 0.04) / r_tip
    segs += [(line(end, out), False)]
    p2 = c + r_tip * np.array([0.0, np.sin(0.4), np.cos(0.4)])
    segs += [(line(out, c + (p2 - c) * (r_tip + 0.04) / r_tip), False),
             (line(c + (p2 - c) * (r_tip + 0.04) / r_tip, p2), False), (arc(0.4, 0.9, np.array([0, 1.0, 0])), True),
             (line(c + r_tip * np.array([0, np.sin(0.9), np.cos(0.9)]), c + (r_tip + 0.05) *
                   np.array([0, np.sin(0.9), np.cos(0.9)])), False)]
    path = np.concatenate([s[0] for s in segs])
    pressing = np.concatenate([np.full(len(s[0]), s[1]) for s in segs])
    return path, pressing


def _header(ts, t: float, frame: str):
    sec = int(math.floor(t))
    return ts["std_msgs/msg/Header"](stamp=ts["builtin_interfaces/msg/Time"](sec=sec, nanosec=int(round(
        (t - sec) * 1e9)) % 1_000_000_000), frame_id=frame)


def _robot_messages(ts, t0, joints, reached, R, pressing, c, tip_radius, press_force, joint_rate, wrench_rate, rng,
                    names) -> tuple[list[BagMessage], list]:
    """The joint states along the path and the wrenches (pressing along the sphere's normal, noise elsewhere) in
    the tool frame; with the true contact points."""
    t_joint = np.arange(len(joints)) / joint_rate
    msgs: list[BagMessage] = []
    for t, qq in zip(t_joint, joints):
        m = ts["sensor_msgs/msg/JointState"](header=_header(ts, t0 + t, ""), name=names, position=qq,
                                             velocity=np.zeros(6), effort=np.zeros(6))
        msgs.append(BagMessage("/joint_states", "sensor_msgs/msg/JointState", int((t0 + t) * 1e9), m))
    t_wrench = np.arange(0.003, t_joint[-1], 1.0 / wrench_rate)
    contact_path = []
    for t in t_wrench:
        i = min(int(t * joint_rate), len(reached) - 2)
        w = t * joint_rate - i
        p = reached[i] * (1 - w) + reached[i + 1] * w
        on = pressing[i] and pressing[i + 1]
        n = (p - c) / np.linalg.norm(p - c)
        f_base = n * press_force if on else rng.normal(0.0, 0.05, 3)
        if on:
            contact_path.append(p - tip_radius * n)
        f_tool = R[i].T @ f_base
        m = ts["geometry_msgs/msg/WrenchStamped"](header=_header(ts, t0 + t, "tool0"), wrench=ts[
            "geometry_msgs/msg/Wrench"](force=ts["geometry_msgs/msg/Vector3"](x=f_tool[0], y=f_tool[1], z=f_tool[2]),
                                        torque=ts["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0)))
        msgs.append(BagMessage("/wrench", "geometry_msgs/msg/WrenchStamped", int((t0 + t) * 1e9), m))
    return msgs, contact_path


#: The wrist camera's optical frame in the flange frame (``camera="wrist"``): 10 cm beside the flange, looking at where
#: the sphere's centre lies below a pressing fingertip.
WRIST_CAMERA = look_at(np.array([0.1, 0.0, 0.0]), np.array([0.0, 0.0, 0.135]), up=(0.0, 1.0, 0.0))
#: The clouds a wrist camera takes, evenly among the joint states where the fingertip presses.
WRIST_CLOUDS = 6


def _camera_messages(ts, t0, T_bo, c, cover_radius, image) -> list[BagMessage]:
    """The camera's static transforms and one organised cloud of the cover (NaN where rays miss, an ``rgb`` field
    and row padding)."""
    msgs = [_camera_static(ts, t0, "base", T_bo)]
    msgs.append(_cloud_message(ts, t0 + 0.01, T_bo, c, cover_radius, image))
    return msgs


def _wrist_camera_messages(ts, t0, flange, times, pressing, c, cover_radius, image) -> list[BagMessage]:
    """A camera on the flange: its static transforms from ``tool0``, the flange's pose `(k, 4, 4)` in ``/tf`` at each
    of ``times`` [s], and :data:`WRIST_CLOUDS` clouds of the cover while ``pressing``, each from the flange then."""
    msgs = [_camera_static(ts, t0, "tool0", WRIST_CAMERA)]
    for t, T in zip(times, flange):
        msgs.append(BagMessage("/tf", "tf2_msgs/msg/TFMessage", int((t0 + t) * 1e9),
                               ts["tf2_msgs/msg/TFMessage"](transforms=[_transform(ts, t0 + t, "base", "tool0", T)])))
    at = np.flatnonzero(pressing)
    for i in at[np.linspace(0, len(at) - 1, WRIST_CLOUDS).round().astype(int)]:
        msgs.append(_cloud_message(ts, t0 + times[i], flange[i] @ WRIST_CAMERA, c, cover_radius, image))
    return sorted(msgs, key=lambda m: m.t_ns)


def _transform(ts, t, parent, child, T):
    tr, qx = T[:3, 3], _matrix_quat(T[:3, :3])
    return ts["geometry_msgs/msg/TransformStamped"](
        header=_header(ts, t, parent), child_frame_id=child, transform=ts["geometry_msgs/msg/Transform"](
            translation=ts["geometry_msgs/msg/Vector3"](x=tr[0], y=tr[1], z=tr[2]),
            rotation=ts["geometry_msgs/msg/Quaternion"](x=qx[0], y=qx[1], z=qx[2], w=qx[3])))


def _camera_static(ts, t0, parent, T_po) -> BagMessage:
    """``parent -> camera_link (x forward) -> camera_depth_optical_frame (z forward)`` in ``/tf_static``, the optical
    frame at ``T_po`` `(4, 4)` in ``parent``."""
    R_link_optical = np.array([[0.0, 0, 1], [-1, 0, 0], [0, -1, 0]])  # REP 103: optical z = link x
    T_lo = np.eye(4)
    T_lo[:3, :3] = R_link_optical
    T_lo[:3, 3] = [0.0, 0.015, 0.0]
    T_pl = T_po @ np.linalg.inv(T_lo)
    tf = ts["tf2_msgs/msg/TFMessage"](transforms=[_transform(ts, t0, parent, "camera_link", T_pl),
                                                  _transform(ts, t0, "camera_link", "camera_depth_optical_frame",
                                                             T_lo)])
    return BagMessage("/tf_static", "tf2_msgs/msg/TFMessage", int(t0 * 1e9), tf)


def _cloud_message(ts, t, T_bo, c, cover_radius, image) -> BagMessage:
    """One organised cloud of the cover seen from the optical frame at ``T_bo`` (NaN where rays miss, an ``rgb``
    field and row padding), stamped ``t`` [s]."""
    h, w = image
    u, v = np.meshgrid(np.linspace(-0.35, 0.35, w), np.linspace(-0.27, 0.27, h))
    rays = np.stack([u, v, np.ones_like(u)], axis=-1)
    rays /= np.linalg.norm(rays, axis=-1, keepdims=True)
    o = np.linalg.inv(T_bo)[:3] @ np.append(c, 1.0)  # sphere centre in the optical frame
    b = rays @ o
    disc = b * b - (o @ o - cover_radius ** 2)
    depth = np.where(disc >= 0, b - np.sqrt(np.maximum(disc, 0)), np.nan)
    pts = (rays * depth[..., None]).astype(np.float32)
    step, pad = 32, 8
    rec = np.zeros((h, w * step + pad), dtype=np.uint8)
    cells = rec[:, :w * step].reshape(h, w, step)
    cells[..., 0:12] = pts.view(np.uint8).reshape(h, w, 12)
    cells[..., 16:20] = np.full((h, w), 0x00FF8800, dtype=np.uint32).view(np.uint8).reshape(h, w, 4)
    field = ts["sensor_msgs/msg/PointField"]
    cloud = ts["sensor_msgs/msg/PointCloud2"](
        header=_header(ts, t, "camera_depth_optical_frame"), height=h, width=w,
        fields=[field(name="x", offset=0, datatype=7, count=1), field(name="y", offset=4, datatype=7, count=1),
                field(name="z", offset=8, datatype=7, count=1), field(name="rgb", offset=16, datatype=7, count=1)],
        is_bigendian=False, point_step=step, row_step=w * step + pad, data=rec.reshape(-1), is_dense=False)
    return BagMessage("/camera/depth/points", "sensor_msgs/msg/PointCloud2", int(t * 1e9), cloud)


def _matrix_quat(R: np.ndarray) -> tuple[float, float, float, float]:
    """(x, y, z, w) of a rotation matrix."""
    from scipy.spatial.transform import Rotation

    return tuple(float(v) for v in Rotation.from_matrix(R).as_quat())
