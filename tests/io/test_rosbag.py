"""ROS 2 bag import: bags written by rosbags' own writer with real message types, checked against the known object."""

import copy
import dataclasses

import numpy as np
import pytest

pytest.importorskip("rosbags")

from torch_gpioius.cli import main  # noqa: E402
from torch_gpioius.io.datasets import load_dataset  # noqa: E402
from torch_gpioius.io.rosbag import (BagImportError, BagTopics, decode_point_cloud2, import_bag,  # noqa: E402
                                     parse_transform, write_bag)
from torch_gpioius.testing.bags import example_bag_messages  # noqa: E402


@pytest.fixture(scope="module")
def recording():
    return example_bag_messages()


@pytest.fixture(scope="module")
def mcap_bag(recording, tmp_path_factory):
    return write_bag(tmp_path_factory.mktemp("bags") / "run", recording[0], storage="mcap")


def _import(path, truth, **kw):
    return import_bag(path, tool_offset=truth["tool_offset"], tip_radius=truth["tip_radius"], **kw)


@pytest.mark.parametrize("storage", ["mcap", "sqlite3"])
def test_import_matches_the_known_object(recording, tmp_path, storage):
    msgs, truth = recording
    bag = write_bag(tmp_path / "run", msgs, storage=storage)
    ds = _import(bag, truth)
    c, r, R = truth["center"], truth["radius"], truth["cover_radius"]
    contacts = ds.x[(ds.task == 0) & (ds.y == 0)]
    free = ds.x[(ds.task == 0) & (ds.y == 1)]
    seen = ds.x[(ds.task == 1) & (ds.y == 0)]
    seen_free = ds.x[(ds.task == 1) & (ds.y == 1)]
    # contacts lie on the inner sphere: interpolation of joints between 3.2 mm samples on a 8.5 cm arc errs by
    # ~1e-5 m; 2e-4 m leaves a margin
    assert len(contacts) >= 10
    np.testing.assert_allclose(np.linalg.norm(contacts - c, axis=1), r, atol=2e-4)
    # and they are thinned to the spacing, in time order with steps 1..k
    d = np.linalg.norm(contacts[:, None] - contacts[None], axis=-1) + np.eye(len(contacts))
    assert d.min() >= 0.005 * (1 - 1e-9)
    np.testing.assert_array_equal(ds.step[(ds.task == 0) & (ds.y == 0)], np.arange(1, len(contacts) + 1))
    # free space: outside the body by at least the tip radius, and the margin away from every contact
    assert len(free) >= 5
    assert (np.linalg.norm(free - c, axis=1) >= r + truth["tip_radius"] - 1e-6).all()
    assert np.linalg.norm(free[:, None] - contacts[None], axis=-1).min() >= 0.02
    # the cloud is in the base frame: voxel means of the 10 cm cover lie within the chord error of a 5 cm voxel
    # on a 10 cm sphere (< 5 mm), on the cap that faces the camera (cos >= R / |eye - c| = 0.15 there)
    np.testing.assert_allclose(np.linalg.norm(seen - c, axis=1), R, atol=5e-3)
    eye = truth["T_base_optical"][:3, 3]
    facing = (seen - c) @ (eye - c) / np.linalg.norm(eye - c) / np.linalg.norm(seen - c, axis=1)
    assert facing.min() > R / np.linalg.norm(eye - c) - 0.1 and np.median(facing) > 0.4
    assert (np.linalg.norm(seen_free - c, axis=1) > R - 5e-3).all()
    assert (ds.step[ds.task == 1] == 0).all()
    assert ds.meta["camera_frames"] == ["camera_depth_optical_frame"] and ds.meta["frame"] == "base"
    assert ds.trace["positions"].shape == (ds.meta["counts"]["wrench"], 3)


def test_cloud_without_voxels_is_exact(recording, mcap_bag):
    from torch_gpioius.exploration.observations import ObservationPolicy

    msgs, truth = recording
    ds = _import(mcap_bag, truth, policy=ObservationPolicy(voxel=None))
    c, R = truth["center"], truth["cover_radius"]
    seen = ds.x[(ds.task == 1) & (ds.y == 0)]
    free = ds.x[(ds.task == 1) & (ds.y == 1)]
    # float32 coordinates of ~0.7 m: ~1e-7 m rounding; 1e-5 leaves a margin
    assert len(seen) == ds.meta["counts"]["cloud_points"] > 100
    np.testing.assert_allclose(np.linalg.norm(seen - c, axis=1), R, atol=1e-5)
    eye = truth["T_base_optical"][:3, 3]
    np.testing.assert_allclose(np.linalg.norm(free - seen, axis=1), 0.05, atol=1e-9)
    assert (np.linalg.norm(free - c, axis=1) > R).all()
    # free space lies on the ray to the camera
    ray = (eye - seen) / np.linalg.norm(eye - seen, axis=1, keepdims=True)
    np.testing.assert_allclose((free - seen) / 0.05, ray, atol=1e-9)


def test_a_bags_voxels_are_chosen_by_the_depth_smoothed_along_the_rays(recording, tmp_path):
    """With ``ray_smoothing`` each frame's measured points are averaged in the voxels their smoothed depths choose, as
    an exploration averages a capture (``vision_observations``): the import of a one-frame bag against the voxel
    means recomputed from its unvoxelled import, not the means of the smoothed points."""
    from torch_gpioius.exploration.observations import ObservationPolicy
    from torch_gpioius.sensors import PointCloud
    from torch_gpioius.geometry.voxels import voxel_average

    msgs, truth = recording
    bag = write_bag(tmp_path / "one", _with(msgs, "/camera/depth/points", lambda ms: ms[:1]), storage="mcap")
    measured = _import(bag, truth, policy=ObservationPolicy(voxel=None))
    measured = measured.x[(measured.task == 1) & (measured.y == 0)]
    smooth = PointCloud(measured, origin=truth["T_base_optical"][:3, 3]).smoothed_along_rays(24).points
    assert np.abs(smooth - measured).max() > 1e-6                  # the smoothing moves them: the check can fail
    ds = _import(bag, truth, policy=ObservationPolicy(voxel=0.02, ray_smoothing=24))
    np.testing.assert_allclose(ds.x[(ds.task == 1) & (ds.y == 0)], voxel_average(measured, 0.02, at=smooth),
                               atol=1e-12)


def test_camera_transform_replaces_tf(recording, mcap_bag):
    msgs, truth = recording
    via_tf = _import(mcap_bag, truth)
    T = truth["T_base_optical"]
    from scipy.spatial.transform import Rotation

    given = " ".join(f"{v:.17g}" for v in [*T[:3, 3], *Rotation.from_matrix(T[:3, :3]).as_quat()])
    via_arg = _import(mcap_bag, truth, camera_transform=given)
    np.testing.assert_allclose(via_arg.x, via_tf.x, atol=1e-9)
    wrong = _import(mcap_bag, truth, camera_transform="0 0 0 0 0 0 1")
    seen = wrong.x[(wrong.task == 1) & (wrong.y == 0)]
    assert np.abs(np.linalg.norm(seen - truth["center"], axis=1) - truth["cover_radius"]).max() > 0.1


def test_cli_import_then_fit_and_replay(mcap_bag, recording, tmp_path, capsys):
    truth = recording[1]
    out = tmp_path / "run.gpioius"
    assert main(["import-bag", str(mcap_bag), "--out", str(out), "--tool-offset", "0 0 0.05",
                 "--tip-radius", str(truth["tip_radius"])]) == 0
    text = capsys.readouterr().out
    assert "wrench samples" in text and "camera_depth_optical_frame -> base" in text
    ds = load_dataset(out)
    assert (ds.task == 0).any() and (ds.task == 1).any()
    assert main(["fit", str(out), "--out", str(tmp_path / "fit")]) == 0
    fitted = capsys.readouterr().out
    assert "correlation = " in fitted
    assert main(["replay", str(out), "--out", str(tmp_path / "replay"), "--every", "8", "--quiet"]) == 0
    # an existing dataset is not replaced without --force (it was, silently)
    before = out.read_bytes()
    assert main(["import-bag", str(mcap_bag), "--out", str(out), "--tool-offset", "0 0 0.05"]) == 2
    assert "run.gpioius: exists; pass --force" in capsys.readouterr().err and out.read_bytes() == before
    assert main(["import-bag", str(mcap_bag), "--out", str(out), "--tool-offset", "0 0 0.05", "--force",
                 "--end", "2.5"]) == 0
    assert load_dataset(out).meta["time_window"] == [0.0, 2.5]
    assert main(["import-bag", str(mcap_bag), "--out", str(out), "--force", "--start", "0.5"]) == 2
    assert "no cloud in the time window from 0.5 s on" in capsys.readouterr().err
    # issue 51, item 9: `import-bag IN --out IN --force` replaced the recording with its own dataset
    recorded = {p: p.read_bytes() for p in ([mcap_bag] if mcap_bag.is_file() else mcap_bag.rglob("*"))
                if p.is_file()}
    inside = mcap_bag / "x.gpioius" if mcap_bag.is_dir() else mcap_bag
    for target in (mcap_bag, inside):
        assert main(["import-bag", str(mcap_bag), "--out", str(target), "--force", "--tool-offset", "0 0 0.05"]) == 2
        assert "the recording" in capsys.readouterr().err
    assert {p: p.read_bytes() for p in recorded} == recorded


def _with(msgs, topic, fn):
    """A copy of the messages where those on ``topic`` pass through ``fn(list) -> list``."""
    keep = [m for m in msgs if m.topic != topic]
    return keep + fn([copy.deepcopy(m) for m in msgs if m.topic == topic])


def _nan_cloud(ms):
    out = []
    for m in ms:
        data = np.asarray(m.msg.data).copy()
        cells = data.reshape(m.msg.height, -1)[:, :m.msg.width * m.msg.point_step].reshape(m.msg.height,
                                                                                           m.msg.width, -1)
        cells[..., 0:12] = np.full((m.msg.height, m.msg.width, 3), np.nan, np.float32).view(np.uint8).reshape(
            m.msg.height, m.msg.width, 12)
        out.append(dataclasses.replace(m, msg=dataclasses.replace(m.msg, data=data)))
    return out


def _rename_fields(ms):
    return [dataclasses.replace(m, msg=dataclasses.replace(m.msg, fields=[dataclasses.replace(f, name=n) for f, n in
                                                                           zip(m.msg.fields, "abcd")])) for m in ms]


def _gap(ms):
    t = np.array([m.t_ns for m in ms])
    mid = t[len(t) // 2]
    return [m for m in ms if not (mid <= m.t_ns < mid + 500_000_000)]


def _backwards(ms):
    a, b = ms[10], ms[11]
    return ms[:10] + [dataclasses.replace(a, msg=b.msg), dataclasses.replace(b, msg=a.msg)] + ms[12:]


def _cloud_field(ms, **change):
    """Clouds whose fields are changed: ``change`` maps a field name to the PointField attributes to set."""
    out = []
    for m in ms:
        fields = [dataclasses.replace(f, **change.get(f.name, {})) for f in m.msg.fields]
        out.append(dataclasses.replace(m, msg=dataclasses.replace(m.msg, fields=fields)))
    return out


def _empty_cloud(ms):
    return [dataclasses.replace(m, msg=dataclasses.replace(m.msg, height=0, width=0, row_step=0,
                                                           data=np.zeros(0, np.uint8))) for m in ms]


def _flip_endian(ms):
    return [dataclasses.replace(m, msg=dataclasses.replace(m.msg, is_bigendian=True)) for m in ms]


def _joint_named_twice(ms):
    names = list(ms[5].msg.name)
    names[-1] = names[0]
    ms[5] = dataclasses.replace(ms[5], msg=dataclasses.replace(ms[5].msg, name=names))
    return ms


def _flipped_bit(ms):
    q = np.asarray(ms[7].msg.position, dtype=np.float64).copy()
    q[1] = (q[1:2].view(np.uint64) ^ np.uint64(1 << 52)).view(np.float64)[0]     # lowest exponent bit: x2 or /2
    ms[7] = dataclasses.replace(ms[7], msg=dataclasses.replace(ms[7].msg, position=q))
    return ms


def _tf(ms, translation=None, rotation=None):
    out = []
    for m in ms:
        tfs = []
        for ts in m.msg.transforms:
            tr = ts.transform
            if translation is not None:
                tr = dataclasses.replace(tr, translation=dataclasses.replace(tr.translation, **translation))
            if rotation is not None:
                tr = dataclasses.replace(tr, rotation=dataclasses.replace(tr.rotation, **rotation))
            tfs.append(dataclasses.replace(ts, transform=tr))
        out.append(dataclasses.replace(m, msg=dataclasses.replace(m.msg, transforms=tfs)))
    return out


FAULTS = {
    "empty cloud": (
        lambda m: _with(m, "/camera/depth/points", _empty_cloud),
        "topic /camera/depth/points: every cloud is empty",
    ),
    "x field twice": (
        lambda m: _with(m, "/camera/depth/points", lambda ms: _cloud_field(ms, rgb={"name": "x"})),
        "declares field 'x' 2 times",
    ),
    "overlapping x/y": (
        lambda m: _with(m, "/camera/depth/points", lambda ms: _cloud_field(ms, y={"offset": 2})),
        "fields 'x' .bytes 0-3. and 'y' .bytes 2-5. overlap",
    ),
    "wrong byte order": (lambda m: _with(m, "/camera/depth/points", _flip_endian), "is_bigendian=True"),
    "joint named twice": (
        lambda m: _with(m, "/joint_states", _joint_named_twice),
        "topic /joint_states: the joint state at t = .* names joint 'shoulder_pan_joint' 2 times",
    ),
    "flipped bit in a joint": (
        lambda m: _with(m, "/joint_states", _flipped_bit),
        "topic /joint_states: joint 'shoulder_lift_joint' moves .* a corrupt joint value",
    ),
    "NaN tf": (
        lambda m: _with(m, "/tf_static", lambda ms: _tf(ms, translation={"x": float("nan")})),
        "topic /tf_static: the transform base -> camera_link at t = .* translation .* is not finite",
    ),
    "zero quaternion tf": (
        lambda m: _with(m, "/tf_static", lambda ms: _tf(ms, rotation={"x": 0.0, "y": 0.0, "z": 0.0, "w": 0.0})),
        "topic /tf_static: the transform base -> camera_link .* is not a rotation",
    ),
    "missing topic": (lambda m: [x for x in m if x.topic != "/wrench"], "topic /wrench is not in the bag"),
    "empty topic": (lambda m: _with(m, "/joint_states", lambda ms: []), "topic /joint_states is not in the bag"),
    "time gap": (lambda m: _with(m, "/joint_states", _gap), "topic /joint_states: a gap of 0.5"),
    "all-NaN cloud": (
        lambda m: _with(m, "/camera/depth/points", _nan_cloud),
        "topic /camera/depth/points: every point",
    ),
    "no x/y/z": (lambda m: _with(m, "/camera/depth/points", _rename_fields), "has no x/y/z field"),
    "clock backwards": (lambda m: _with(m, "/wrench", _backwards), "topic /wrench: the clock runs backwards"),
    "no camera pose": (lambda m: [x for x in m if x.topic != "/tf_static"], "no transform from"),
}


@pytest.mark.parametrize("fault", sorted(FAULTS))
def test_bad_bags_give_one_line_naming_topic_and_cause(recording, tmp_path, fault, capsys):
    msgs, truth = recording
    change, expected = FAULTS[fault]
    bag = write_bag(tmp_path / "bad", change(list(msgs)), storage="mcap")
    with pytest.raises(BagImportError, match=expected):
        _import(bag, truth)
    assert main(["import-bag", str(bag), "--out", str(tmp_path / "x.gpioius")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("gpioius: error:") and "\n" not in err and expected.split(":")[0].split()[-1] in err
    assert not (tmp_path / "x.gpioius").exists()


def test_wrong_message_type_empty_bag_and_not_a_bag(recording, mcap_bag, tmp_path):
    truth = recording[1]
    with pytest.raises(BagImportError, match="topic /joint_states carries sensor_msgs/msg/JointState, expected "
                                              "geometry_msgs/msg/WrenchStamped"):
        _import(mcap_bag, truth, topics=BagTopics(wrench="/joint_states"))
    empty = write_bag(tmp_path / "empty", [], storage="sqlite3")
    with pytest.raises(BagImportError, match="the bag has no topics"):
        _import(empty, truth)
    junk = tmp_path / "junk.mcap"
    junk.write_bytes(b"not a bag at all")
    with pytest.raises(BagImportError, match="not a readable ROS 2 bag"):
        _import(junk, truth)
    with pytest.raises(BagImportError, match="no such bag"):
        _import(tmp_path / "nowhere", truth)


def test_no_contact_and_bad_arguments(recording, tmp_path):
    msgs, truth = recording
    bag = write_bag(tmp_path / "b", msgs, storage="mcap")
    with pytest.raises(BagImportError, match=r"topic /wrench: no sample reaches \|F\| >= 50 N"):
        _import(bag, truth, contact_force=50.0)
    with pytest.raises(ValueError, match="max_gap"):
        _import(bag, truth, max_gap=float("nan"))
    for bad in ("1 2 3", "0 0 0 0 0 0 0", "a b c d e f g"):
        with pytest.raises(ValueError, match="transform|quaternion"):
            parse_transform(bad)


def test_decode_point_cloud2_layouts():
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS2_HUMBLE).types
    field, header = ts["sensor_msgs/msg/PointField"], ts["std_msgs/msg/Header"]
    pts = np.array([[1.0, 2.0, 3.0], [np.nan, 0.0, 0.0], [-4.0, 5.5, 6.25]])
    # big-endian float64, fields in z, x, y order with an int field between, unorganised
    rec = np.zeros(3, dtype=np.dtype({"names": ["z", "i", "x", "y"], "formats": [">f8", ">i4", ">f8", ">f8"],
                                      "offsets": [0, 8, 12, 20], "itemsize": 32}))
    rec["x"], rec["y"], rec["z"] = pts.T
    msg = ts["sensor_msgs/msg/PointCloud2"](
        header=header(stamp=ts["builtin_interfaces/msg/Time"](sec=0, nanosec=0), frame_id="c"), height=1, width=3,
        fields=[field(name="z", offset=0, datatype=8, count=1), field(name="i", offset=8, datatype=5, count=1),
                field(name="x", offset=12, datatype=8, count=1), field(name="y", offset=20, datatype=8, count=1)],
        is_bigendian=True, point_step=32, row_step=96, data=rec.view(np.uint8), is_dense=False)
    np.testing.assert_array_equal(decode_point_cloud2(msg), pts[[0, 2]])
    short = dataclasses.replace(msg, data=rec.view(np.uint8)[:50])
    with pytest.raises(BagImportError, match="does not hold 1 x 3 points"):
        decode_point_cloud2(short)


def _repeat_clouds(ms, copies):
    """``copies`` clouds: the recording's cloud again every 50 ms (as a camera streams frames)."""
    return [dataclasses.replace(m, t_ns=m.t_ns + k * 50_000_000,
                                msg=dataclasses.replace(m.msg, header=dataclasses.replace(
                                    m.msg.header, stamp=dataclasses.replace(
                                        m.msg.header.stamp, nanosec=m.msg.header.stamp.nanosec + k * 50_000_000))))
            for m in ms for k in range(copies)]


def test_clouds_are_streamed_into_the_voxels_and_a_time_window_selects(tmp_path):
    """Many frames average to what one frame gives (the same cloud repeated: the same voxel means), while the
    memory held does not grow with the number of frames (each is dropped once it is in the voxels)."""
    import tracemalloc

    msgs, truth = example_bag_messages(image=(180, 240))
    peaks, data = {}, {}
    for copies in (1, 8):
        bag = write_bag(tmp_path / f"b{copies}", _with(msgs, "/camera/depth/points",
                                                      lambda ms: _repeat_clouds(ms, copies)), storage="mcap")
        tracemalloc.start()
        data[copies] = _import(bag, truth)
        peaks[copies] = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
    assert data[8].meta["counts"]["clouds"] == 8
    one, eight = (d.x[d.task == 1] for d in (data[1], data[8]))
    np.testing.assert_allclose(eight, one, atol=1e-12)            # the same voxel means, to summation rounding
    frame = 180 * 240 * 32                                        # bytes of one frame in the bag
    # the reader buffers an MCAP chunk (a few frames); holding all 8 frames and their points would add > 15
    assert peaks[8] < peaks[1] + 4 * frame, (peaks, frame)
    # a time window from 0.1 s on: the wrench samples before it and the two clouds stamped 0.007 and 0.057 s after
    # the first sample are left out
    end = float(data[8].trace["timestamps"][-1])
    w = import_bag(tmp_path / "b8", tool_offset=truth["tool_offset"], tip_radius=truth["tip_radius"],
                   time_window=(0.1, end))
    assert w.meta["counts"]["wrench"] < data[8].meta["counts"]["wrench"] and w.meta["counts"]["clouds"] == 6
    with pytest.raises(BagImportError, match=r"no cloud in the time window 5-6 s"):
        import_bag(tmp_path / "b1", tool_offset=truth["tool_offset"], time_window=(5.0, 6.0))
    with pytest.raises(ValueError, match="time_window"):
        import_bag(tmp_path / "b1", time_window=(2.0, 1.0))


# ----------------------------------------------------------------------------------------------- a gel pad topic
def _pad_frames(recording, every=1, bad=None):
    """The recording plus depth frames (32FC1) of a gel pad fixed to the fingertip, rendered from the true sphere at
    the joint states' stamps: every ``every``-th joint sample while pressing, and two out of contact. The pad faces
    the sphere at the first press (its gel 1 mm inside it there) and keeps that mount; frames pressed beyond the
    gel's reach are not recorded (a gel bottoms out). Returns ``(messages, T_tool_pad, calibration)``."""
    import torch
    from kinematics.ur5 import UR5
    from rosbags.typesys import Stores, get_typestore

    from torch_gpioius.io.rosbag import BagMessage
    from torch_gpioius.sensors.tactile import TactileCalibration
    from torch_gpioius.sensors.simulated.gelpad import pad_pose

    msgs, truth = recording
    ts = get_typestore(Stores.ROS2_HUMBLE).types
    cal = TactileCalibration(pitch=5e-4, gel_thickness=3e-3, contact_depth=1e-4)
    c, r = np.asarray(truth["center"]), truth["radius"]
    ur5 = UR5(tool_offset=truth["tool_offset"])
    wrench = sorted((m.t_ns, np.linalg.norm([m.msg.wrench.force.x, m.msg.wrench.force.y, m.msg.wrench.force.z]))
                    for m in msgs if m.topic == "/wrench")
    t_w, f_w = np.array([w[0] for w in wrench]), np.array([w[1] for w in wrench])
    joints = [m for m in msgs if m.topic == "/joint_states"]
    pressing = [m for m in joints if f_w[np.argmin(np.abs(t_w - m.t_ns))] >= 1.0]
    loose = [m for m in joints if f_w[np.argmin(np.abs(t_w - m.t_ns))] < 0.5]
    T = {m.t_ns: ur5.forward_kinematics(torch.as_tensor(np.asarray(m.msg.position))).detach().numpy()
         for m in pressing + loose[::50]}
    first = T[pressing[0].t_ns]
    n0 = (first[:3, 3] - c) / np.linalg.norm(first[:3, 3] - c)
    pad0 = pad_pose(c + (r - 1e-3) * n0, -n0)                  # z into the sphere, the gel 1 mm inside it
    T_tool_pad = np.linalg.inv(first) @ pad0
    h = w = 40
    jj, ii = np.meshgrid(np.arange(w) - (w - 1) / 2, np.arange(h) - (h - 1) / 2)
    plane = np.stack([jj * cal.pitch, ii * cal.pitch, np.zeros_like(jj, dtype=float)], -1).reshape(-1, 3)
    out = []
    for m in pressing[::every] + loose[::50][:2]:
        pose = T[m.t_ns] @ T_tool_pad
        o = plane @ pose[:3, :3].T + pose[:3, 3]
        axis = pose[:3, 2]
        b = (o - c) @ axis
        disc = b * b - (((o - c) ** 2).sum(1) - r * r)
        s = np.where(disc >= 0, -b - np.sqrt(np.maximum(disc, 0.0)), np.inf)   # the sphere's front, pad z
        depth = np.where(s < 0, -s, np.nan).reshape(h, w)
        if np.nanmax(depth, initial=0.0) > cal.gel_thickness:
            continue
        data = depth.astype(np.float32)
        img = ts["sensor_msgs/msg/Image"](header=m.msg.header, height=h, width=w, encoding="32FC1", is_bigendian=0,
                                          step=4 * w, data=data.view(np.uint8).reshape(-1))
        if bad is not None:
            img = bad(img)
        out.append(BagMessage("/digit/depth", "sensor_msgs/msg/Image", m.t_ns, img))
    return msgs + out, T_tool_pad, cal


def test_a_pad_topic_imports_patches_on_the_known_object(recording, tmp_path):
    from torch_gpioius.exploration.patches import PatchThinning

    msgs, T_tool_pad, cal = _pad_frames(recording)
    truth = recording[1]
    bag = write_bag(tmp_path / "pad", msgs, storage="mcap")
    ds = _import(bag, truth, topics=BagTopics(tactile="/digit/depth"), tactile_calibration=cal,
                 tactile_transform=T_tool_pad, patch=PatchThinning(spacing=0.002))
    counts = ds.meta["counts"]
    assert counts["pad_frames_used"] >= 3 and counts["pad_frames_out_of_contact"] == 2
    assert counts["pad_frames"] == counts["pad_frames_used"] + counts["pad_frames_out_of_contact"] + \
        counts["pad_frames_untouched"]
    assert counts["patch_surface"] > 10 * counts["pad_frames_used"] // 2
    inner = ds.task == 0
    surf = ds.x[inner & (ds.y == 0)]
    c, r = truth["center"], truth["radius"]
    # the patches lie on the sphere: joints at their own stamps (no interpolation), float32 depths of <= 3 mm
    # (~4e-10 m); the fingertip contacts beside them as before (2e-4 m, interpolation)
    on = np.abs(np.linalg.norm(surf - c, axis=1) - r)
    assert (on < 2e-4).all() and (np.sort(on)[:counts["patch_surface"]] < 1e-8).all()
    # thinned across frames to the patch spacing, and every inner free point the margins away from them
    d = np.linalg.norm(surf[:, None] - surf[None], axis=-1) + np.eye(len(surf))
    patch_pts = surf[on < 1e-8]
    dp = np.linalg.norm(patch_pts[:, None] - patch_pts[None], axis=-1) + np.eye(len(patch_pts))
    assert dp.min() >= 0.002 * (1 - 1e-9) and d.min() > 0
    free = ds.x[inner & (ds.y == 1)]
    assert np.linalg.norm(free[:, None] - patch_pts[None], axis=-1).min() >= 0.02 - 1e-12
    assert ds.meta["bag_topics"]["tactile"] == "/digit/depth" and ds.meta["tactile"]["calibration"]["pitch"] == 5e-4


@pytest.mark.parametrize("bad, match", [
    (lambda img: dataclasses.replace(img, encoding="rgb8"), "not a depth encoding"),
    (lambda img: dataclasses.replace(img, data=(np.full((img.height, img.width), 5e-3, np.float32)
                                                .view(np.uint8).reshape(-1))), "reach"),
    (lambda img: dataclasses.replace(img, data=img.data[:-4]), "do not hold"),
])
def test_bad_pad_frames_are_refused_naming_the_topic(recording, tmp_path, bad, match):
    msgs, T_tool_pad, cal = _pad_frames(recording, every=40, bad=bad)
    bag = write_bag(tmp_path / "bad", msgs, storage="mcap")
    with pytest.raises(BagImportError, match=f"/digit/depth: the frame at t = .*{match}"):
        _import(bag, recording[1], topics=BagTopics(tactile="/digit/depth"), tactile_calibration=cal,
                tactile_transform=T_tool_pad)
    with pytest.raises(ValueError, match="tactile_calibration"):
        _import(bag, recording[1], topics=BagTopics(tactile="/digit/depth"))


def test_cli_imports_a_pad_topic(recording, tmp_path, capsys):
    from scipy.spatial.transform import Rotation

    msgs, T_tool_pad, cal = _pad_frames(recording)
    bag = write_bag(tmp_path / "pad", msgs, storage="mcap")
    qx, qy, qz, qw = Rotation.from_matrix(T_tool_pad[:3, :3]).as_quat()
    pose = " ".join(f"{v:.17g}" for v in (*T_tool_pad[:3, 3], qx, qy, qz, qw))
    out = tmp_path / "pad.gpioius"
    truth = recording[1]
    assert main(["import-bag", str(bag), "--out", str(out), "--tool-offset", " ".join(map(str, truth["tool_offset"])),
                 "--tip-radius", str(truth["tip_radius"]), "--tactile-topic", "/digit/depth", "--tactile-pitch",
                 str(cal.pitch), "--tactile-gel", str(cal.gel_thickness), "--tactile-contact-depth",
                 str(cal.contact_depth), "--tactile-transform", pose]) == 0
    text = capsys.readouterr().out
    ds = load_dataset(out)
    assert f"{ds.meta['counts']['patch_surface']} surface" in text and ds.meta["counts"]["pad_frames_used"] >= 3


def test_a_bag_imported_with_the_default_settings_has_inside_points_behind_its_contacts(recording, mcap_bag):
    """Issue 52: offline data gets what exploration gets. With the default settings each contact has an inside
    point 2 cm behind it along the measured force (on the recorded sphere: radially, 2 cm under the surface), with
    the contact's step and label; the paper's settings place none, and none lies behind the seen surface."""
    from torch_gpioius.models.estimator import EstimatorSettings

    msgs, truth = recording
    c, r = truth["center"], truth["radius"]
    ds = _import(mcap_bag, truth, settings="default")
    labels = EstimatorSettings.default().labels
    inner = ds.task == 0
    contacts, inside = inner & (ds.y == 0), inner & (ds.y < 0)
    touched = contacts.sum() / labels.contact_repeats                  # each contact as often as a run counts it
    assert inside.sum() >= 0.8 * touched and ds.meta["counts"]["inside_points"] == int(inside.sum())
    np.testing.assert_allclose(ds.y[inside], labels.inside_label(labels.touch_inside))
    # the force is the sphere's normal to the joint interpolation's error (~1e-5 m on the contact; the force's
    # direction within a degree): 2e-4 m of margin
    np.testing.assert_allclose(np.linalg.norm(ds.x[inside] - c, axis=1), r - labels.touch_inside, atol=2e-4)
    step_of = dict(zip(ds.step[contacts], ds.x[contacts]))
    for p, k in zip(ds.x[inside], ds.step[inside]):
        assert np.linalg.norm(step_of[k] - p) == pytest.approx(labels.touch_inside, abs=1e-9)
    assert not ((ds.task == 1) & (ds.y < 0)).any()
    assert ds.meta["estimator"]["labels"]["touch_inside"] == labels.touch_inside
    assert ds.meta["estimator"]["labels"]["vision_inside"] is None
    paper = _import(mcap_bag, truth, settings="paper")
    assert not (paper.y < 0).any() and paper.meta["counts"]["inside_points"] == 0


def test_a_bags_contacts_enter_as_often_as_an_exploration_repeats_them(recording, mcap_bag):
    """``contact_repeats``: each contact of the bag k times, with its step; the count of contacts says how many were
    touched, and everything else is the import with one each."""
    from torch_gpioius.models.overrides import EstimatorOverrides

    msgs, truth = recording
    one = _import(mcap_bag, truth, settings=EstimatorOverrides(labels={"contact_repeats": 1}))
    three = _import(mcap_bag, truth, settings=EstimatorOverrides(labels={"contact_repeats": 3}))
    n = one.meta["counts"]["contacts"]
    assert three.meta["counts"]["contacts"] == n
    touched = lambda ds: (ds.task == 0) & (ds.y == 0)                    # noqa: E731
    assert touched(three).sum() == touched(one).sum() + 2 * n
    np.testing.assert_array_equal(three.x[touched(three)][::3], one.x[touched(one)][:n])
    np.testing.assert_array_equal(three.step[touched(three)][::3], one.step[touched(one)][:n])
    assert len(three) == len(one) + 2 * n


# ------------------------------------------------------------------------------------ a camera whose pose is off
def _off_by(T: np.ndarray, translation: float, degrees: float, seed: int) -> str:
    """``T`` `(4, 4)` moved by ``translation`` [m] and turned by ``degrees`` about its own origin, each in a seeded
    direction, as ``"x y z qx qy qz qw"``: a calibration that is off."""
    from scipy.spatial.transform import Rotation

    rng = np.random.default_rng(seed)
    d, a = rng.standard_normal(3), rng.standard_normal(3)
    R = Rotation.from_rotvec(np.radians(degrees) * a / np.linalg.norm(a)).as_matrix() @ T[:3, :3]
    t = T[:3, 3] + translation * d / np.linalg.norm(d)
    return " ".join(f"{v:.17g}" for v in [*t, *Rotation.from_matrix(R).as_quat()])


def _cover_centre_error(ds, truth) -> float:
    """How far [m] the sphere fitted to the imported cover's seen points lies from the true cover's centre (least
    squares, algebraic: the points' own fit, independent of the correction's)."""
    seen = ds.x[(ds.task == 1) & (ds.y == 0)]
    solution = np.linalg.lstsq(np.c_[2 * seen, np.ones(len(seen))], (seen ** 2).sum(axis=1), rcond=None)[0]
    return float(np.linalg.norm(solution[:3] - truth["center"]))


def test_a_fixed_cameras_clouds_are_corrected_from_the_contacts_within_the_bound(tmp_path):
    """A camera transform off by 6 mm and a degree (the cover's centre then 1-1.5 cm off): with camera_bound the
    clouds, as one capture, move towards the contacts (the fitted cover's centre at least a third closer), the
    dataset records the correction within its bound, and a calibrated camera is left nearly as it is."""
    msgs, truth = example_bag_messages(image=(120, 160))
    bag = write_bag(tmp_path / "run", msgs, storage="mcap")
    T = truth["T_base_optical"]
    for seed in (1, 3):
        given = _off_by(T, 0.006, 1.0, seed)
        off = _import(bag, truth, camera_transform=given)
        fixed = _import(bag, truth, camera_transform=given, camera_bound="12mm,2deg")
        assert _cover_centre_error(off, truth) > 0.008
        assert _cover_centre_error(fixed, truth) < 2 / 3 * _cover_centre_error(off, truth)
        record = fixed.meta["camera_corrections"]
        assert record["enough"] and len(record["captures"]) == 1
        moved = record["captures"][0]
        assert 0 < moved["size_mm"] <= 12 + 1e-9 and moved["angle_deg"] <= 2 + 1e-9
        # measured as given too (the contacts within what the bound allows), and the correction lowers it
        assert record["misfit_after_mm"] < record["misfit_before_mm"]
        assert "camera_corrections" not in off.meta
    calibrated = _import(bag, truth, camera_bound="12mm,2deg")
    moved = calibrated.meta["camera_corrections"]["captures"][0]
    assert moved["size_mm"] < 2.0 and moved["angle_deg"] < 0.3
    assert _cover_centre_error(calibrated, truth) < _cover_centre_error(_import(bag, truth), truth) + 0.0015


def test_camera_bound_refuses_clouds_whose_pose_changes_and_bad_bounds(recording, tmp_path):
    """A correction is one camera's: clouds in two frames that tf places apart (a camera on the arm, or two
    cameras) are refused, naming the topic and why; a bound that is not one is refused before the bag is read."""
    msgs, truth = recording

    def two_frames(ms):
        other = [dataclasses.replace(m, t_ns=m.t_ns + 50_000_000, msg=dataclasses.replace(
            m.msg, header=dataclasses.replace(m.msg.header, frame_id="camera_link"))) for m in ms]
        return ms + other

    bag = write_bag(tmp_path / "two", _with(msgs, "/camera/depth/points", two_frames), storage="mcap")
    _import(bag, truth)                                        # as they are: both frames' clouds, through tf
    with pytest.raises(BagImportError, match=r"/camera/depth/points: camera_bound corrects one camera fixed"):
        _import(bag, truth, camera_bound="12mm,2deg")
    with pytest.raises(ValueError, match="camera_bound"):
        _import(bag, truth, camera_bound="12mm")


def _hand_eye_off(msgs, translation: float, degrees: float, seed: int):
    """The recording with its ``tool0 -> camera_link`` transform moved by ``translation`` [m] and turned by
    ``degrees`` about the camera link, in seeded directions (the rotation vector [rad] in tool0's frame is returned
    with it): a wrist camera whose hand-eye calibration is off."""
    from scipy.spatial.transform import Rotation

    rng = np.random.default_rng(seed)
    d, a = rng.standard_normal(3), rng.standard_normal(3)

    def moved(ms):
        for m in ms:
            for ts in m.msg.transforms:
                if ts.child_frame_id != "camera_link":
                    continue
                tr, q = ts.transform.translation, ts.transform.rotation
                R = Rotation.from_rotvec(np.radians(degrees) * a / np.linalg.norm(a)) * Rotation.from_quat(
                    [q.x, q.y, q.z, q.w])
                x, y, z, w = R.as_quat()
                q.x, q.y, q.z, q.w = x, y, z, w
                shift = translation * d / np.linalg.norm(d)
                tr.x, tr.y, tr.z = tr.x + shift[0], tr.y + shift[1], tr.z + shift[2]
        return ms

    return _with(msgs, "/tf_static", moved), np.radians(degrees) * a / np.linalg.norm(a)


@pytest.fixture(scope="module")
def wrist():
    return example_bag_messages(image=(120, 160), camera="wrist")


def test_a_wrist_cameras_hand_eye_error_is_corrected_once_for_every_cloud(wrist, tmp_path):
    """A camera on the flange whose hand-eye transform is off by 6 mm and a degree: its six clouds, each from the
    flange's pose then, are misplaced by that one error as the flange placed them. With camera_bound and camera_mount
    the clouds share one correction in the flange's frame (recorded with the frame): the overlaps of clouds taken from
    different flange positions fix its rotation (recovered to within 0.4 degree of the applied one, on three seeds),
    the contacts the rest they can; what a sphere's contacts on its top cannot fix (a slide along it) is named weak.
    A calibrated camera is left nearly as it is; without the mount the moving camera is refused, naming it."""
    msgs, truth = wrist
    calibrated = write_bag(tmp_path / "calibrated", msgs, storage="mcap")
    kept = _import(calibrated, truth, camera_bound="12mm,2deg", camera_mount="tool0")
    record = kept.meta["camera_corrections"]
    assert record["mount_frame"] == "tool0" and record["mount"]["size_mm"] < 2.0 and record["mount"]["angle_deg"] < 0.5
    for seed in (1, 2):
        given, rotation = _hand_eye_off(msgs, 0.006, 1.0, seed)
        bag = write_bag(tmp_path / f"off{seed}", given, storage="mcap")
        fixed = _import(bag, truth, camera_bound="12mm,2deg", camera_mount="tool0")
        record = fixed.meta["camera_corrections"]
        assert record["enough"] and len(record["captures"]) == 6 and record["mount"]["contacts"] >= 10
        assert 0 < record["mount"]["size_mm"] <= 12 + 1e-9 and record["mount"]["angle_deg"] <= 2 + 1e-9
        left = np.radians(record["mount"]["rotation_deg"]) + rotation     # the correction undoes the error
        assert np.degrees(np.linalg.norm(left)) < 0.4, (record["mount"], np.degrees(rotation))
        assert record["mount"]["weak"] and record["misfit_after_mm"] < record["misfit_before_mm"]
        # every cloud moved by the mount's correction as its flange pose placed it: one rotation seen from the base
        first = record["captures"][0]["rotation_deg"]
        assert all(np.allclose(c["rotation_deg"], first, atol=0.01) for c in record["captures"])
    with pytest.raises(BagImportError, match="give camera_mount"):
        _import(calibrated, truth, camera_bound="12mm,2deg")
    with pytest.raises(BagImportError, match="camera_mount: no transform from 'wrist_3' to 'base'"):
        _import(calibrated, truth, camera_bound="12mm,2deg", camera_mount="wrist_3")
    with pytest.raises(ValueError, match="give camera_bound too"):
        _import(calibrated, truth, camera_mount="tool0")
    with pytest.raises(ValueError, match="camera_transform fixes one pose"):
        _import(calibrated, truth, camera_bound="12mm,2deg", camera_mount="tool0",
                camera_transform="0 0 0 0 0 0 1")


def test_cli_import_bag_corrects_the_camera_and_says_by_how_much(tmp_path, capsys):
    msgs, truth = example_bag_messages(image=(120, 160))
    bag = write_bag(tmp_path / "run", msgs, storage="mcap")
    given = _off_by(truth["T_base_optical"], 0.006, 1.0, 1)
    assert main(["import-bag", str(bag), "--out", str(tmp_path / "d.gpioius"), "--tool-offset", "0 0 0.05",
                 "--tip-radius", str(truth["tip_radius"]), "--camera-transform", given,
                 "--camera-bound", "12mm,2deg"]) == 0
    line = next(t for t in capsys.readouterr().out.splitlines() if t.startswith("camera:"))
    assert "to agree with the touches" in line
    record = load_dataset(tmp_path / "d.gpioius").meta["camera_corrections"]
    assert f"moved {record['captures'][0]['size_mm']:.1f} mm" in line


def test_cli_import_bag_corrects_a_wrist_camera_on_its_mount(wrist, tmp_path, capsys):
    msgs, truth = wrist
    given, _ = _hand_eye_off(msgs, 0.006, 1.0, 1)
    bag = write_bag(tmp_path / "run", given, storage="mcap")
    assert main(["import-bag", str(bag), "--out", str(tmp_path / "d.gpioius"), "--tool-offset", "0 0 0.05",
                 "--tip-radius", str(truth["tip_radius"]), "--camera-bound", "12mm,2deg",
                 "--camera-mount", "tool0"]) == 0
    line = next(t for t in capsys.readouterr().out.splitlines() if t.startswith("camera on tool0:"))
    record = load_dataset(tmp_path / "d.gpioius").meta["camera_corrections"]
    assert f"moved {record['mount']['size_mm']:.1f} mm" in line and "the contacts' misfit" in line
    assert main(["import-bag", str(bag), "--out", str(tmp_path / "e.gpioius"), "--camera-mount", "tool0"]) == 2
    assert "give camera_bound too" in capsys.readouterr().err
