"""Tactile pads: readings, calibration, adapters, and a patch as observations checked on an analytic sphere."""

import math
from types import SimpleNamespace

import numpy as np
import pytest
import torch

import torch_gpioius as tg
from torch_gpioius.exploration.patches import PatchThinning, patch_observations
from torch_gpioius.sensors.tactile import (DIGIT_CALIBRATION, DepthMapTactileSensor, DigitTactileSensor,
                                           TactileCalibration, TactileReading, depth_from_image_message)

CAL = TactileCalibration(pitch=1e-4, gel_thickness=3e-3, contact_depth=1e-4)


def _pose(seed=0):
    rng = np.random.default_rng(seed)
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    q *= np.sign(np.linalg.det(q))
    pose = np.eye(4)
    pose[:3, :3], pose[:3, 3] = q, rng.normal(size=3) * 0.3
    return pose


def _sphere_reading(radius=0.02, press=1e-3, shape=(160, 200), pose=None, cal=CAL):
    """A sphere pressed ``press`` into the gel: its centre on the pad's +z axis at radius - press (pad frame)."""
    h, w = shape
    jj, ii = np.meshgrid(np.arange(w), np.arange(h))
    x, y = (jj - (w - 1) / 2) * cal.pitch, (ii - (h - 1) / 2) * cal.pitch
    r2 = x ** 2 + y ** 2
    zs = (radius - press) - np.sqrt(np.maximum(radius ** 2 - r2, 0.0))      # the sphere's near surface
    depth = np.where((r2 < radius ** 2) & (zs < 0), -zs, np.nan)
    pose = np.eye(4) if pose is None else pose
    centre = pose[:3, :3] @ np.array([0.0, 0.0, radius - press]) + pose[:3, 3]
    return TactileReading(depth, pose, cal), centre


@pytest.mark.parametrize("seed", [None, 1])
def test_a_pressed_sphere_gives_points_on_it_normals_of_it_and_free_space_outside_it(seed):
    pose = None if seed is None else _pose(seed)
    radius = 0.02
    reading, centre = _sphere_reading(radius, pose=pose)
    settings = PatchThinning(spacing=0.001, free_spacing=0.002, free_margin=0.002)
    obs = patch_observations(reading, settings, step=3)
    surf, free = obs.x[obs.y == 0], obs.x[obs.y == 1]
    assert obs.source == "patch" and obs.step == 3 and (obs.task == 0).all()
    # the contact disc: radius sqrt(2 R press - press^2) ~ 6.2 mm at 1 mm pressed, so ~ 100 points at 1 mm spacing
    assert 60 < len(surf) < 160 and len(free) > 20
    dist = np.linalg.norm(surf - centre, axis=1)
    assert np.abs(dist - radius).max() < 1e-12                        # exactly on the sphere (analytic depth)
    spacing = np.linalg.norm(surf[:, None] - surf[None], axis=-1) + np.eye(len(surf))
    assert spacing.min() >= settings.spacing * (1 - 1e-9)
    # normals: outward sphere normals, up to the central difference's O(pitch^2 / R^2) error
    nrm = obs.normal[obs.y == 0]
    known = np.isfinite(nrm).all(1)
    assert known.mean() > 0.9
    true_n = (surf - centre) / radius
    angle = np.degrees(np.arccos(np.clip((nrm[known] * true_n[known]).sum(1), -1, 1)))
    assert angle.max() < 1.0, angle.max()
    assert np.isnan(obs.normal[obs.y == 1]).all()
    # free space: outside the sphere, at least free_margin from every surface point
    assert (np.linalg.norm(free - centre, axis=1) >= radius - 1e-12).all()
    gap = np.linalg.norm(free[:, None] - surf[None], axis=-1).min(1)
    assert gap.min() >= settings.free_margin - 1e-12
    # deepest first: the first point is the pressed centre
    assert np.linalg.norm(surf[0] - (centre - radius * (pose if pose is not None else np.eye(4))[:3, 2])) < 2e-4


def test_a_patch_does_not_depend_on_rounding_of_its_depths():
    """A sphere pressed square on the pad has rings of pixels of equal depth; a 1e-16 m perturbation (another CPU,
    a resumed run) must not change which of them the thinning keeps."""
    reading, _ = _sphere_reading()
    rng = np.random.default_rng(0)
    nudged = TactileReading(reading.depth * (1 + 1e-15 * rng.standard_normal(reading.depth.shape)), reading.pose,
                            reading.calibration)
    a, b = patch_observations(reading), patch_observations(nudged)
    assert a.x.shape == b.x.shape and np.array_equal(a.y, b.y)
    assert np.abs(a.x - b.x).max() < 1e-15


def test_a_patch_feeds_the_model_and_its_estimate_passes_through_the_sphere():
    reading, centre = _sphere_reading(0.03, press=1.5e-3, shape=(200, 200))
    obs = patch_observations(reading, PatchThinning(spacing=0.002, free_spacing=0.003, free_margin=0.003))
    model = tg.GPIS(
        torch.tensor(obs.x), torch.tensor(obs.y), kernel=tg.kernels.InverseMultiquadricKernel(0.05), noise=1e-3
    ).fit()
    mu, _ = model.predict(torch.tensor(obs.x[obs.y == 0]))
    assert float(mu.abs().max()) < 0.2


@pytest.mark.parametrize("depth, match", [
    (np.zeros(10), "H, W"), (np.zeros((1, 10)), "H, W"), (np.full((4, 4), np.inf), "inf"),
    (np.full((4, 4), 5e-3), "reach"), (np.full((4, 4), -1e-3), "reach"), (np.full((4, 4), 2.0), "reach"),
])
def test_bad_depth_maps_are_refused_with_their_defect(depth, match):
    with pytest.raises(ValueError, match=match):
        TactileReading(depth, np.eye(4), CAL)


@pytest.mark.parametrize("pose, match", [
    (np.full((4, 4), np.nan), "NaN"), (np.eye(3), "4, 4"), (np.diag([2.0, 1, 1, 1]), "rigid"),
    (np.diag([1.0, 1, -1, 1]), "rigid"),
])
def test_bad_poses_are_refused(pose, match):
    with pytest.raises(ValueError, match=match):
        TactileReading(np.zeros((4, 4)), pose, CAL)


def test_an_all_nan_map_is_a_fault_and_the_model_is_left_alone():
    model = tg.GPIS(
        torch.zeros(1, 3, dtype=torch.float64), torch.zeros(1), kernel=tg.kernels.InverseMultiquadricKernel(0.05)
    )
    n = model.train_targets.numel()
    reading = TactileReading(np.full((8, 8), np.nan), np.eye(4), CAL)
    with pytest.raises(ValueError, match="all NaN"):
        obs = patch_observations(reading)
        model.add_observations(torch.tensor(obs.x), torch.tensor(obs.y))
    assert model.train_targets.numel() == n


def test_a_light_touch_is_free_space_only():
    depth = np.full((20, 20), 5e-5)                 # pressed, but less than contact_depth everywhere
    obs = patch_observations(TactileReading(depth, np.eye(4), CAL))
    assert len(obs) > 0 and (obs.y == 1).all()


@pytest.mark.parametrize("kwargs", [{"pitch": 0.0}, {"pitch": math.nan}, {"gel_thickness": 1.0},
                                    {"contact_depth": 4e-3}, {"pitch": True}])
def test_bad_calibrations_are_refused(kwargs):
    args = {"pitch": 1e-4, "gel_thickness": 3e-3, "contact_depth": 1e-4, **kwargs}
    with pytest.raises(ValueError, match="TactileCalibration"):
        TactileCalibration(**args)


def test_settings_are_checked():
    with pytest.raises(ValueError, match="spacing"):
        PatchThinning(spacing=-1.0)


def test_depth_map_adapter_checks_each_frame():
    frames = iter(
        [(np.zeros((6, 8)), np.eye(4)), (np.zeros((8, 6)), np.eye(4)), (np.zeros((6, 8)), np.full((4, 4), np.nan))]
    )
    sensor = DepthMapTactileSensor(lambda: next(frames), CAL, shape=(6, 8), clock=lambda: 1.5)
    assert isinstance(sensor, tg.sensors.tactile.TactileSensor)
    reading = sensor.read()
    assert reading.shape == (6, 8) and reading.stamp == 1.5
    with pytest.raises(ValueError, match="shape"):
        sensor.read()
    with pytest.raises(ValueError, match="pose"):
        sensor.read()
    with pytest.raises(ValueError, match="callable"):
        DepthMapTactileSensor(None, CAL)


def test_digit_adapter_runs_the_users_image_to_depth():
    image = np.zeros((240, 320, 3), np.uint8)
    image[100:140, 140:180] = 200                      # a pressed square, as the user's model would see it
    digit = SimpleNamespace(get_frame=lambda: image)

    def to_depth(img):
        return np.where(img[..., 0] > 0, 1e-3, np.nan)

    sensor = DigitTactileSensor(digit, to_depth, lambda: np.eye(4))
    reading = sensor.read()
    assert reading.calibration == DIGIT_CALIBRATION and int(reading.contact_mask.sum()) == 1600
    obs = patch_observations(reading)
    assert (obs.y == 0).sum() > 0 and np.allclose(obs.normal[obs.y == 0][0], [0, 0, -1])
    bad = DigitTactileSensor(digit, lambda img: np.zeros((10, 10)), lambda: np.eye(4))
    with pytest.raises(ValueError, match="image_to_depth"):
        bad.read()
    with pytest.raises(ValueError, match="get_frame"):
        DigitTactileSensor(object(), to_depth, lambda: np.eye(4))


def _image(data: np.ndarray, encoding: str, bigendian: bool = False, pad: int = 0):
    h, w = data.shape
    raw = data.astype(data.dtype.newbyteorder(">" if bigendian else "<")).tobytes()
    rows = [raw[i * w * data.itemsize:(i + 1) * w * data.itemsize] + b"\0" * pad for i in range(h)]
    return SimpleNamespace(height=h, width=w, encoding=encoding, is_bigendian=bigendian,
                           step=w * data.itemsize + pad, data=np.frombuffer(b"".join(rows), np.uint8))


def test_ros_depth_images_decode_to_metres():
    mm = np.array([[0, 1500], [250, 65535]], dtype=np.uint16)
    out = depth_from_image_message(_image(mm, "16UC1", pad=4))
    assert np.isnan(out[0, 0]) and out[0, 1] == 1.5 and out[1, 0] == 0.25
    m = np.array([[0.5, 1.25], [np.nan, 2.0]], dtype=np.float32)
    out = depth_from_image_message(_image(m, "32FC1", bigendian=True))
    assert out[0, 1] == 1.25 and np.isnan(out[1, 0])
    with pytest.raises(ValueError, match="not a depth encoding"):
        depth_from_image_message(_image(m, "rgb8"))
    msg = _image(m, "32FC1")
    msg.data = msg.data[:-1]
    with pytest.raises(ValueError, match="bytes"):
        depth_from_image_message(msg)
