"""The simulated depth camera's errors beyond its depth noise (a calibration that is off, pixels and blocks lost) and
what it keeps apart (the table), against analytic geometry."""

import numpy as np
import pytest
import trimesh

from torch_gpioius.sensors import PinholeCamera, SimulatedDepthCamera, look_at

from tests.sensors.spheres import C, EYE, R, sphere_camera


def test_a_camera_without_embree_says_so_once(monkeypatch):
    """Issue 54, item 3: without embreex a plain install ran the simulated camera on trimesh's Python engine (43 %
    of a run) and said nothing."""
    import warnings
    from types import SimpleNamespace

    from trimesh.ray.ray_triangle import RayMeshIntersector

    import torch_gpioius.sensors.simulated.camera as pc

    monkeypatch.setattr(pc, "_SAID", set())
    mesh = trimesh.creation.icosphere(subdivisions=2, radius=0.1)
    mesh.apply_translation(C)
    cam = SimulatedDepthCamera(mesh, PinholeCamera.kinect_v2(0.15), look_at(EYE, C))
    cam.mesh = SimpleNamespace(ray=RayMeshIntersector(mesh))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        first, again = cam.capture(), cam.capture()
    said = [w for w in caught if "embreex is not installed" in str(w.message)]
    assert len(said) == 1 and len(first) == len(again) > 50


def test_a_camera_error_parses_sizes_with_units_and_refuses_what_is_not_one():
    from torch_gpioius.sensors.simulated.camera import CameraError

    e = CameraError.parse("6mm,1deg")
    assert e.translation == pytest.approx(0.006) and e.rotation == pytest.approx(np.radians(1.0))
    assert CameraError.parse(" 1deg , 0.5cm ") == CameraError(0.005, np.radians(1.0))
    assert CameraError.parse("0.01rad") == CameraError(0.0, 0.01) and not CameraError.parse("0")
    assert CameraError.parse(str(e)) == e                       # its text reads back
    for text, match in (("6,1deg", "not a size with a unit"), ("6mm,2mm", "translation twice"), ("6in", "unit"),
                        ("1deg,2deg", "rotation twice"), ("20cm", r"translation must be in \[0, 0.1\]"),
                        ("-1mm", "translation"), ("30deg", "rotation"), ("nanmm", "translation"),
                        ("2x,3x", "noise twice"), ("200x", "noise"), ("96%", "dropout"), ("-5%holes", "holes"),
                        ("x", "not a size")):
        with pytest.raises(ValueError, match=match):
            CameraError.parse(text)
    # the sensing terms: a multiple of the depth noise, pixels and blocks lost; none of them moves a capture
    worse = CameraError.parse("2x, 20%, 10%holes,6mm,1deg")
    assert (worse.noise, worse.dropout, worse.holes) == (2.0, pytest.approx(0.2), pytest.approx(0.1))
    assert worse.extrinsic and worse.sensing and CameraError.parse(str(worse)) == worse
    only = CameraError.parse("3x")
    assert only and not only.extrinsic and only.drawn(0) is None and CameraError.parse(str(only)) == only
    # a world's fingerprint of an extrinsic error alone is as before the sensing terms existed
    assert e.fingerprint() == [[e.translation, e.rotation]] and CameraError().fingerprint() == []
    assert e.check_bound() is e
    for bound, match in ((worse, "a bound is a translation and a rotation"), (CameraError(0.006), "give both")):
        with pytest.raises(ValueError, match=match):
            bound.check_bound()


def test_worse_sensing_scales_the_depth_noise_and_loses_pixels_and_blocks():
    """A camera error's sensing terms, against the camera model's own: ``3x`` triples the depth noise's standard
    deviation along each ray (the same pixels), ``40%`` loses that share of the pixels at random, ``25%holes`` a
    quarter of the image's blocks, whole: the pixels kept are exactly those outside the lost blocks."""
    from torch_gpioius.sensors.simulated.camera import CameraError, HOLE_BLOCKS

    clean = sphere_camera().capture()
    d_clean = np.linalg.norm(clean.points - EYE, axis=1)
    normal = sphere_camera(noise_a=0.001, seed=3).capture()
    tripled = sphere_camera(noise_a=0.001, seed=3, error=CameraError.parse("3x")).capture()
    assert len(tripled) == len(normal) == len(clean)
    # the same draw, three times as far along the same rays
    np.testing.assert_allclose(np.linalg.norm(tripled.points - EYE, axis=1) - d_clean,
                               3 * (np.linalg.norm(normal.points - EYE, axis=1) - d_clean), atol=1e-12)
    dropped = sphere_camera(error=CameraError.parse("40%"), seed=1).capture()
    assert 0.55 * len(clean) < len(dropped) < 0.65 * len(clean)
    cam = sphere_camera(error=CameraError.parse("25%holes"), seed=2)
    holed = cam.capture()
    intr = cam.intrinsics
    size = intr.width / HOLE_BLOCKS

    def block(points):
        p = (points - EYE) @ cam.T_base_camera[:3, :3]
        u, v = intr.fx * p[:, 0] / p[:, 2] + intr.cx, intr.fy * p[:, 1] / p[:, 2] + intr.cy
        return (v // size).astype(int) * HOLE_BLOCKS + (u // size).astype(int)

    seen, kept = set(block(clean.points)), set(block(holed.points))
    assert kept < seen and 0.5 * len(seen) < len(kept) < 0.95 * len(seen)     # whole blocks lost, most kept
    lost = seen - kept
    assert not np.isin(block(holed.points), list(lost)).any()
    assert (~np.isin(block(clean.points), list(lost))).sum() == len(holed)    # every pixel outside them kept
    # anew each capture
    assert set(block(cam.capture().points)) != kept


def test_a_camera_off_by_a_rigid_error_sees_the_sphere_moved_by_it_and_keeps_its_noise():
    """Closed form: the captured sphere (radius R about C) lies, with the error, on a sphere of radius R about the
    moved centre c + R_e (C - c) + t (c the camera's optical centre); the error has exactly the asked sizes, its
    direction drawn from the seed; the depth noise is the same draw with and without it."""
    from torch_gpioius.sensors.simulated.camera import CameraError

    error = CameraError.parse("6mm,1deg")
    plain, off = sphere_camera(noise_a=0.001, seed=3), sphere_camera(noise_a=0.001, seed=3, error=error)
    applied = off.applied_error
    assert plain.applied_error is None
    assert np.linalg.norm(applied.translation) == pytest.approx(0.006, rel=1e-12)
    Rm = applied.matrix()
    np.testing.assert_allclose(Rm @ Rm.T, np.eye(3), atol=1e-14)
    assert np.degrees(np.arccos((np.trace(Rm) - 1) / 2)) == pytest.approx(1.0, rel=1e-9)
    a, b = plain.capture(), off.capture()
    np.testing.assert_allclose(b.origin, EYE)                   # the camera says it stands where it was calibrated
    moved = EYE + Rm @ (C - EYE) + np.asarray(applied.translation)
    r = np.linalg.norm(b.points - moved, axis=1)
    assert np.abs(r - R).max() < 2e-4 + 5 * 0.001               # the icosphere's sag and the depth noise (5 sigma)
    # the same pixels and noise, only moved: distances between points are kept to rounding
    np.testing.assert_allclose(np.linalg.norm(b.points[1:] - b.points[:-1], axis=1),
                               np.linalg.norm(a.points[1:] - a.points[:-1], axis=1), atol=1e-12)
    assert np.linalg.norm(b.points - a.points, axis=1).min() > 1e-3   # and really moved (6 mm and 1 deg at 1 m)
    # each seed its own direction; the same seed the same one; reseeded keeps the sizes
    again = off.reseeded(4).applied_error
    assert again != applied and off.reseeded(3).applied_error == applied
    assert np.linalg.norm(again.rotation) == pytest.approx(np.radians(1.0), rel=1e-12)
    rec = applied.as_record()
    assert rec["size_mm"] == pytest.approx(6.0) and rec["angle_deg"] == pytest.approx(1.0)


def test_a_simulated_camera_keeps_the_table_it_sees_apart_and_the_object_as_without_it():
    """A box on a table at z = 0.1: the camera's table points (``support``) lie on the plane (no noise: exactly),
    within the reach around the box, none behind the box; the box's points, noise and dropout drawn from the same
    seed, are those of the same camera without a table."""
    import trimesh

    from torch_gpioius.sensors.simulated.camera import SUPPORT_REACH, SimulatedDepthCamera
    from torch_gpioius.sensors.pointcloud import PinholeCamera, look_at

    box = trimesh.creation.box((0.1, 0.1, 0.1))
    box.apply_translation([0.5, 0.0, 0.15])
    pose = look_at([0.0, -0.6, 0.7], [0.5, 0.0, 0.15])
    bare = SimulatedDepthCamera(box, PinholeCamera.kinect_v2(0.25), pose, support=0.1)
    table = bare.capture().support
    assert len(table) > 100 and np.abs(table[:, 2] - 0.1).max() < 1e-9
    lo, hi = box.bounds[0][:2] - SUPPORT_REACH, box.bounds[1][:2] + SUPPORT_REACH
    assert ((table[:, :2] >= lo - 1e-9) & (table[:, :2] <= hi + 1e-9)).all()
    assert not ((np.abs(table[:, 0] - 0.5) < 0.05) & (np.abs(table[:, 1]) < 0.05)).any()   # not under the box
    kw = dict(noise_a=0.0015, noise_b=0.0015, dropout=0.1, seed=4)
    with_table = SimulatedDepthCamera(box, PinholeCamera.kinect_v2(0.25), pose, support=0.1, **kw).capture()
    without = SimulatedDepthCamera(box, PinholeCamera.kinect_v2(0.25), pose, **kw).capture()
    np.testing.assert_array_equal(with_table.points, without.points)
    assert without.support is None and len(with_table.support) > 50
    with pytest.raises(ValueError, match="support"):
        SimulatedDepthCamera(box, PinholeCamera.kinect_v2(0.25), pose, support=float("nan"))
