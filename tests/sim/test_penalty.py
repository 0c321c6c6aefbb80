"""3-D exploration on the simulated UR5: a short sphere exploration converges, the robot stays within its limits,
the metrics agree with analytic geometry, the log replays to the same model."""

import numpy as np
import pytest

import torch_gpioius as tg
from kinematics import tool_rotation
from torch_gpioius.exploration import thin_points
from torch_gpioius.sim import estimate_metrics_3d, sphere_scene
from torch_gpioius.geometry.surfaces import surface_samples

C, R = np.array([0.5, 0.0, 0.25]), 0.08


@pytest.fixture(scope="module")
def runs():
    scene = sphere_scene(radius=R, cover=0.01, center=C)
    return scene, {mode: tg.explore(scene, mode=mode, max_travel=0.25, metrics_every=4) for mode in
                   ("visual-tactile", "tactile")}


def test_short_sphere_exploration_converges(runs):
    scene, traces = runs
    for mode, tr in traces.items():
        assert tr.terminated == "travel" and tr.travel[-1] >= 0.25
        # contacts lie on the inner sphere: 1..5 N into a 1000 N/m surface is 1..5 mm, plus sensor noise
        r = np.linalg.norm(tr.contacts - C, axis=1)
        assert np.all(r < R + 1e-3) and np.all(r > R - 0.0065), mode
        # each step slid about alpha = 1 cm between contacts
        steps = np.linalg.norm(np.diff(tr.contacts, axis=0), axis=1)
        assert np.median(steps) == pytest.approx(0.01, abs=0.003)
        h = tr.hausdorff[~np.isnan(tr.hausdorff)]
        assert h[-1] < h[0] and h[-1] < (0.035 if mode == "visual-tactile" else 0.08), (mode, h)
        assert tr.uncertainty[-1] < tr.uncertainty[0]
    vt, ta = traces["visual-tactile"], traces["tactile"]
    assert vt.hausdorff[-1] < ta.hausdorff[-1]        # the 1 cm cover makes vision worth having
    assert vt.hausdorff[0] < ta.hausdorff[0]
    assert np.isnan(ta.similarity).all() and np.isfinite(vt.similarity).all()
    assert vt.final_mesh is not None and scene.in_range(vt.final_mesh.triangles_center).all()


def test_the_range_penalty_keeps_contacts_near_the_range(runs):
    scene, traces = runs
    for tr in traces.values():
        z_min = scene.range[0, 2]
        assert tr.contacts[:, 2].min() > z_min - 0.03


def test_metrics_agree_with_the_analytic_sphere():
    scene = sphere_scene(radius=R, cover=0.01, center=C)
    rng = np.random.default_rng(0)
    d = rng.standard_normal((150, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    x = np.concatenate([C + R * d, C + (R + 0.06) * d[:60]])
    y = np.r_[np.zeros(150), np.ones(60)]
    model = tg.GPIS(x, y, kernel=tg.kernels.InverseMultiquadricKernel(0.15), noise=0.006)
    m = estimate_metrics_3d(model, scene, resolution=0.01)
    est = surface_samples(m.surface, 0.003)
    est = est[scene.in_range(est)]
    # independent: analytic distance to the sphere from the estimate; from the sphere to the estimate by sampling
    out = np.abs(np.linalg.norm(est - C, axis=1) - R).max()
    assert m.hausdorff >= out - 1e-3
    assert m.hausdorff < 0.02
    assert 0 < m.uncertainty < 0.05


def test_log_replays_to_the_final_training_set(tmp_path):
    scene = sphere_scene(radius=R, cover=0.01, center=C)
    log = tmp_path / "sphere.gpioius"
    tr = tg.explore(scene, max_travel=0.05, metrics_every=100, log=log)
    ds = tg.load_dataset(log)
    np.testing.assert_allclose(ds.x, tr.model.train_inputs[0].numpy())
    np.testing.assert_array_equal(ds.y, tr.model.train_targets.numpy())
    assert ds.meta["dim"] == 3 and ds.meta["frame"] == "base"
    assert ds.trace["positions"].shape[1] == 3 and len(ds.trace["forces"]) == len(ds.trace["positions"])
    assert np.isfinite(tr.hausdorff[-1])                     # the last record is always measured


def test_robot_trajectory_respects_the_gate(runs):
    scene = sphere_scene(radius=R, cover=0.01, center=C)
    made = []
    original = scene.hardware
    scene.hardware = lambda: made.append(original()) or made[-1]     # keep the hardware the loop builds
    tr = tg.explore(scene, mode="tactile", max_travel=0.05, metrics_every=100)
    hw = made[0]
    times, qs = hw.robot.trajectory()
    gate = hw.robot.gate
    assert bool(hw.robot.ur5.within_limits(qs).all())
    speed = (qs[1:] - qs[:-1]).abs() / (times[1:] - times[:-1]).clamp_min(1e-12)[:, None]
    assert float(speed.max()) <= float(gate.max_joint_speed.max()) + 1e-9
    tips = hw.robot.ur5.position(qs)
    assert bool(gate.in_workspace(tips).all())
    np.testing.assert_allclose(hw.robot.read_pose()[:3, 2].numpy(), scene.direction, atol=1e-6)  # orientation held
    assert len(tr.path) > 0


def test_helpers():
    for d in ([0, 0, -1], [1, 0, 0], [0.3, -0.2, 0.9]):
        Rm = tool_rotation(d).numpy()
        np.testing.assert_allclose(Rm.T @ Rm, np.eye(3), atol=1e-12)
        np.testing.assert_allclose(Rm[:, 2], np.asarray(d) / np.linalg.norm(d), atol=1e-12)
        assert np.linalg.det(Rm) == pytest.approx(1.0)
    pts = np.random.default_rng(2).uniform(0, 0.1, (300, 3))
    avoid = np.array([[0.05, 0.05, 0.05]])
    kept = thin_points(pts, 0.02, avoid, 0.03)
    gaps = np.linalg.norm(kept[:, None] - kept[None], axis=-1) + np.eye(len(kept))
    assert gaps.min() >= 0.02 and np.linalg.norm(kept - avoid, axis=1).min() >= 0.03
    # every dropped point is near a kept one or near the avoided point (greedy cover)
    far = np.linalg.norm(pts - avoid, axis=1) >= 0.03
    near = np.linalg.norm(pts[far][:, None] - kept[None], axis=-1).min(axis=1)
    assert near.max() < 0.02


def test_bad_calls():
    scene = sphere_scene()
    with pytest.raises(ValueError, match="mode"):
        tg.explore(scene, mode="vision")
    with pytest.raises(ValueError, match="max_travel"):
        tg.explore(scene, max_travel=0.0)
    with pytest.raises(TypeError, match="World"):
        tg.explore("sphere")
    from kinematics import SafetyViolation

    with pytest.raises(SafetyViolation, match="workspace"):   # an approach away from the object hits the gate
        far = sphere_scene()
        far.direction = np.array([0.0, 0.0, 1.0])
        tg.explore(far, mode="tactile", max_travel=0.05)
