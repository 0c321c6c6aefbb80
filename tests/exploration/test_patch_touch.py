"""touch="patch": a simulated gel pad explores a 3-D object; its points are on the body (plus the cloth)."""

import numpy as np
import pytest

import torch_gpioius as tg
from torch_gpioius.exploration.registry import make_world
from torch_gpioius.exploration.touch import PatchTouch
from torch_gpioius.io.datasets import read_records, replay
from torch_gpioius.io.runs import load_run
from torch_gpioius.models.overrides import EstimatorOverrides


@pytest.mark.parametrize("mode", ["visual-tactile", "tactile"])
def test_a_simulated_pad_explores_the_arm_and_its_patches_lie_on_the_body(mode, tmp_path):
    world = make_world("forcefield", "E", 0, smoke=True)
    log = tmp_path / "run.gpioius"
    # the reference: every point of each patch (the default keeps the informative ones, tested below)
    trace = tg.explore(world, mode, touch=PatchTouch(max_points=None), max_travel=0.03, metrics_every=100, log=log)
    assert trace.n_steps >= 3 and not trace.terminated.startswith("refused")
    m = trace.model
    task = m.train_task if mode == "visual-tactile" else np.zeros(m.train_targets.numel(), np.int64)
    inner = np.asarray(task) == 0
    x, y = m.train_inputs[0].numpy()[inner], m.train_targets.numpy()[inner]
    surf = x[y == 0]
    assert len(surf) > 20 * trace.n_steps                       # tens of surface points per touch
    # on the body to within the pinched cloth (0.5 mm) and the pad's 0.5 mm pixels
    dist = world.true_distance(surf)
    assert np.abs(dist).max() < 2e-3, np.abs(dist).max()
    assert (world.true_distance(x[y == 1]) > 0).all()           # free space is outside the body
    if mode == "visual-tactile":
        assert type(trace.model._inference()).__name__ == "BatchedExactInference"
    # the log holds every patch: replaying it gives the model's data
    last = None
    for _, dataset in replay(log):
        last = dataset
    assert last is not None and len(last.y) == trace.model.train_targets.numel()
    # and every pad: a 2 x 2 cm square per step, its patch's surface points under it (within the gel's reach)
    run = load_run(log)
    pads = run.pad_footprints(run.steps[-1])
    assert pads.shape == (len(run.steps), 4, 3)
    sides = np.linalg.norm(pads - np.roll(pads, -1, axis=1), axis=-1)
    assert np.allclose(sides, 0.02, atol=1e-12)
    for r in read_records(log):
        if r.kind == "step" and r.meta["step"] > 0:              # the step's batch: its patch, then free space
            pose, x, y, task = (r.arrays[k] for k in ("pad_pose", "x", "y", "task"))
            local = (x[(y == 0) & (task == 0)] - pose[:3, 3]) @ pose[:3, :3]
            assert len(local) > 10
            assert (np.abs(local[:, :2]) <= 0.01 + 1e-9).all() and (np.abs(local[:, 2]) <= 3e-3 + 1e-9).all()


def test_the_viewer_draws_the_pads_of_a_patch_run(tmp_path):
    from torch_gpioius.viewer import RunViewer

    log = tmp_path / "run.gpioius"
    tg.explore(make_world("forcefield", "E", 0, smoke=True), "tactile", touch="patch", max_travel=0.02,
               metrics_every=100, log=log, progress=False)
    viewer = RunViewer(log, port=0)
    try:
        steps = viewer.run.steps
        viewer.show(steps[-1])
        pads = viewer._handles["/touch/pads"]
        assert pads.visible and len(pads.points) == 4 * len(steps)
        # issue 35, item 20: "807 contacts" stood beside "11 of 11": pad points were counted as touches
        assert f"{len(steps)} touches (" in viewer.info.content and "pad surface points)" in viewer.info.content
        viewer.show(steps[0])
        assert len(viewer._handles["/touch/pads"].points) == 4
        assert "1 touch (" in viewer.info.content
    finally:
        viewer.close()


def test_a_world_without_a_pad_says_so():
    world = make_world("planar", "A", 0)
    with pytest.raises(ValueError, match="no tactile pad"):
        tg.explore(world, "tactile", touch="patch", max_steps=2)
    assert PatchTouch().describe()["touch"] == "patch"


def test_a_patch_run_cut_after_a_step_resumes(tmp_path):
    """Resuming binds the new hardware's pad and restores the re-learning rule's memory (the last Hessian, the
    held fits), so the resumed step makes the same decision with the same K_t. This needs the patch to be the
    same although a freshly built factorisation differs from a bordered one by rounding (~1e-16 m on the next
    contact): the patch orders its pixels by depth to 1e-9 m (symmetric contacts have rings of equal depth).
    Bit-equality beyond the first resumed step is not promised: the sliding exploration amplifies rounding."""
    from torch_gpioius.sim import sphere_scene

    scene = sphere_scene(subdivisions=3)
    kw = dict(mode="visual-tactile", touch="patch", max_travel=0.05, metrics_every=100, progress=False)
    log = tmp_path / "run.gpioius"
    reference = tg.explore(scene, log=log, **kw)
    assert reference.n_steps > 4
    copy = tmp_path / "reference.gpioius"
    copy.write_bytes(log.read_bytes())
    end = next(r.end for r in read_records(log) if r.kind == "step" and r.meta["step"] == 2)
    with open(log, "r+b") as f:
        f.truncate(end)
    resumed = tg.explore(scene, resume_from=log, **kw)
    assert resumed.terminated == reference.terminated and abs(resumed.n_steps - reference.n_steps) <= 1
    assert np.abs(resumed.contacts[:4] - reference.contacts[:4]).max() < 1e-9      # through the first resumed step
    assert np.abs(resumed.task_covariance[:4] - reference.task_covariance[:4]).max() < 1e-9
    decisions = [[r.meta.get("fit_relearned") for r in read_records(f) if r.kind == "step"][:4] for f in (log, copy)]
    assert decisions[0] == decisions[1]
    assert type(resumed.model._inference()).__name__ == "BatchedExactInference"


def test_a_patch_keeps_the_contact_and_its_most_uncertain_points_and_bounds_what_it_drops():
    """PatchTouch.select against an independent dense posterior: the contact first, then the points of largest
    posterior variance, at most max_points and none below min_variance of the prior variance; the dropped points'
    information bound is 1/2 sum log(1 + v / sigma^2) over them; the path's free space is always kept."""
    from torch_gpioius.exploration.observations import Observations
    from tests import reference as ref

    rng = np.random.default_rng(0)
    a = rng.uniform(0, 2 * np.pi, 40)
    seen = np.c_[0.1 * np.cos(a), 0.1 * np.sin(a), rng.uniform(-0.05, 0.05, 40)]
    touched = np.array([[0.1, 0.0, 0.0], [0.0, 0.1, 0.0]])
    x = np.r_[touched, seen, 1.5 * seen]
    y = np.r_[0.0, 0.0, np.zeros(40), np.ones(40)]
    task = np.r_[0, 0, np.ones(80, dtype=int)]
    model = tg.GPIOIS(x, y, task, kernel=tg.kernels.InverseMultiquadricKernel(0.1), noise=0.006).fit()
    # a patch of 30 points around a new contact (its first row), then 3 free-space points of the path
    patch = np.r_[[[0.0, -0.1, 0.0]], [[0.0, -0.1, 0.0]] + rng.normal(0, 0.02, (29, 3))]
    path = np.array([[0.0, -0.2, 0.0], [0.0, -0.22, 0.0], [0.0, -0.24, 0.0]])
    touch = PatchTouch(max_points=8, min_variance=0.05)
    touch._patch_rows = len(patch)
    obs = Observations(np.r_[patch, path], np.r_[np.zeros(30), np.ones(3)], np.zeros(33, np.int64), step=3)
    kept = touch.select(model, obs)
    # the independent posterior variance: a dense solve of the same Gram matrix (tests/reference.py)
    var = ref.posterior(x, y, task, model.task_covariance.numpy(), 0.1, 0.006, patch, 0)[1]
    rel = var / (model.task_covariance[0, 0].item() / 0.1)
    rest = 1 + np.argsort(-rel[1:], kind="stable")
    want = [0] + [i for i in rest if rel[i] >= 0.05][:7]
    np.testing.assert_allclose(kept.x[:-3], patch[sorted(want)], atol=0)
    np.testing.assert_allclose(kept.x[-3:], path, atol=0)
    dropped = np.setdiff1d(np.arange(30), want)
    n, nats = touch.last_dropped
    assert n == len(dropped) == 30 - len(want) and nats == pytest.approx(0.5 * np.log1p(var[dropped] / 0.006).sum(),
                                                                        rel=1e-8)
    assert len(want) <= 8 and kept.step == 3
    # the reference keeps everything
    assert len(PatchTouch(max_points=None).select(model, obs)) == 33
    with pytest.raises(ValueError, match="max_points"):
        PatchTouch(max_points=0)
    with pytest.raises(ValueError, match="min_variance"):
        PatchTouch(min_variance=1.5)


def test_a_default_patch_run_adds_at_most_max_points_per_touch_and_logs_what_it_dropped(tmp_path):
    log = tmp_path / "run.gpioius"
    trace = tg.explore(make_world("forcefield", "E", 0, smoke=True), "visual-tactile", touch="patch",
                       max_travel=0.03, metrics_every=100, log=log)
    assert trace.n_steps >= 3
    dropped = 0
    for r in read_records(log):
        if r.kind == "step" and r.meta["step"] > 0:
            x, y, task = (r.arrays[k] for k in ("x", "y", "task"))
            pose = r.arrays["pad_pose"]
            local = (x - pose[:3, 3]) @ pose[:3, :3]
            on_pad = (np.abs(local[:, :2]) <= 0.01 + 1e-9).all(axis=1) & (np.abs(local[:, 2]) <= 3e-3 + 1e-9)
            assert on_pad.sum() <= 12                                   # the patch's rows: at most max_points
            assert r.arrays["patch_dropped"][0] >= 0 and r.arrays["patch_dropped_nats"][0] >= 0.0
            dropped += int(r.arrays["patch_dropped"][0])
    assert dropped > 0
    # each record says how far its K_t is predicted to be from the optimum (0 after a full re-learning); the log
    # keeps it, and the last one is the model's own
    gaps = [r.meta["fit_gap"] for r in read_records(log) if r.kind == "step"]
    assert np.allclose(gaps, trace.fit_gap, rtol=0, atol=0) and (trace.fit_gap >= 0).all()
    fit = trace.model.fit_result
    assert trace.fit_gap[-1] == (0.0 if fit.relearned else fit.predicted_gain)


def test_the_relearning_settings_are_checked_described_and_passed_to_the_fit():
    touch = PatchTouch()
    assert touch.fit_options() == {"min_gain": 0.1, "track": True, "scout": 256, "max_hold": 30}
    assert touch.describe()["relearn"] == {"track": True, "scout": 256, "max_hold": 30}
    # the schedule of logs written before tracking describes as they do, so they resume
    assert "relearn" not in PatchTouch(track=False, scout=None, max_hold=20).describe()
    for bad in ({"track": 1}, {"scout": 1}, {"scout": 3.0}, {"scout": True}, {"max_hold": 0}, {"max_hold": None}):
        with pytest.raises(ValueError, match=f"PatchTouch.{next(iter(bad))}"):
            PatchTouch(**bad)


def test_a_patch_touch_adds_one_inside_point_behind_its_contact(tmp_path):
    import dataclasses

    world = make_world("forcefield", "E", 0, smoke=True)
    policy = dataclasses.replace(world.defaults.policy, touch_inside=0.02)
    log = tmp_path / "run.gpioius"
    trace = tg.explore(world, "visual-tactile", touch="patch", settings=EstimatorOverrides(policy=policy),
                       max_travel=0.03, metrics_every=100, log=log)
    steps = [r for r in read_records(log) if r.kind == "step" and r.meta["step"] > 0]
    assert len(steps) >= 3
    for r in steps:
        x, y = r.arrays["x"], r.arrays["y"]
        assert (y < 0).sum() == 1 and y[y < 0][0] == pytest.approx(-0.4)
        behind = x[y < 0][0]
        assert np.linalg.norm(behind - r.arrays["contact"]) == pytest.approx(0.02, abs=1e-12)
        assert world.true_distance(behind[None])[0] < -0.01          # in the body, not just under the cover
    assert (trace.model.train_targets < 0).sum() >= len(steps)
