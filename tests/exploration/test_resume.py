"""A real exploration process killed with SIGKILL mid-way loses no completed step and resumes to the same end."""

import os
import signal
import subprocess
import sys
import time
import warnings

import numpy as np
import pytest
import torch

import torch_gpioius as tg
from torch_gpioius.io.datasets import TornLogWarning, read_records
from torch_gpioius.models.overrides import EstimatorOverrides
from torch_gpioius.sim import paper_objects_2d

STEPS = 24
CHILD = """
import sys
import torch_gpioius as tg
from torch_gpioius.sim import paper_objects_2d
import torch_gpioius.io.datasets as ex
orig = ex.LogWriter.append
def append(self, kind, meta, arrays):
    orig(self, kind, meta, arrays)            # durable (fsync) when this returns
    if kind == "step":
        print("durable", meta["step"], flush=True)
ex.LogWriter.append = append
tg.explore(paper_objects_2d()["A"], max_steps=int(sys.argv[2]), log=sys.argv[1])
"""


@pytest.mark.skipif(not hasattr(signal, "SIGKILL"), reason="needs SIGKILL")
def test_sigkill_then_resume(tmp_path):
    log = tmp_path / "run.gpioius"
    proc = subprocess.Popen([sys.executable, "-c", CHILD, str(log), str(STEPS)], stdout=subprocess.PIPE, text=True)
    acknowledged = -1
    deadline = time.monotonic() + 240
    while acknowledged < 8 and time.monotonic() < deadline:
        line = proc.stdout.readline()
        if not line:
            break
        acknowledged = int(line.split()[1])
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    assert proc.returncode == -signal.SIGKILL and 8 <= acknowledged < STEPS

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", TornLogWarning)
        logged = [r.meta["step"] for r in read_records(log) if r.kind == "step"]
    assert logged == list(range(len(logged))) and logged[-1] >= acknowledged   # nothing completed is lost
    assert logged[-1] < STEPS                                                  # it really was cut short

    resumed = tg.explore(paper_objects_2d()["A"], max_steps=STEPS, resume_from=log)
    reference = tg.explore(paper_objects_2d()["A"], max_steps=STEPS)
    assert resumed.n_steps == reference.n_steps and resumed.terminated == reference.terminated
    assert np.abs(resumed.contacts - reference.contacts).max() < 1e-9
    assert np.abs(resumed.path - reference.path).max() < 1e-9
    assert np.abs(resumed.task_covariance - reference.task_covariance).max() < 1e-9
    assert np.allclose(resumed.hausdorff, reference.hausdorff, atol=1e-9, equal_nan=True)
    # the log now holds the whole run and ends with its termination record
    records = list(read_records(log))
    assert [r.meta["step"] for r in records if r.kind == "step"] == list(range(STEPS + 1))
    assert records[-1].kind == "end" and records[-1].meta["terminated"] == reference.terminated
    final = tg.load_dataset(log)
    assert np.allclose(final.x, reference.model.train_inputs[0].numpy(), atol=1e-12)


def test_resume_refuses_other_parameters(tmp_path):
    log = tmp_path / "run.gpioius"
    tg.explore(paper_objects_2d()["A"], max_steps=2, log=log)
    with pytest.raises(ValueError, match="mode"):
        tg.explore(paper_objects_2d()["A"], mode="tactile", max_steps=2, resume_from=log)
    with pytest.raises(ValueError, match="scene"):
        tg.explore(paper_objects_2d()["B"], max_steps=2, resume_from=log)
    done = tg.explore(paper_objects_2d()["A"], max_steps=2, resume_from=log)   # already finished: returns it
    assert done.n_steps == 3


def _cut_after_step(log, k):
    """Truncate a log right after the record of step ``k`` (what a crash after that step leaves behind)."""
    end = next(r.end for r in read_records(log) if r.kind == "step" and r.meta["step"] == k)
    with open(log, "r+b") as f:
        f.truncate(end)


@pytest.mark.parametrize("inside, learn", [(False, "task"), (True, "task"), (True, "all")],
                         ids=["paper-labels", "inside-points", "learned-length-and-noise"])
def test_3d_run_resumes_with_robot_and_sensor_state(tmp_path, inside, learn):
    """The force-field world: the robot's joints and clock and the sensor's noise generator travel in the log, so a
    run cut after step 4 and resumed ends where the uninterrupted run ends; so do inside points (labels below 0),
    and a length and noise learned at step 3 (the log's raw parameters, restored to the bit)."""
    import dataclasses

    from torch_gpioius.sim import sphere_scene

    scene = sphere_scene(subdivisions=3)
    scene.sensor_noise = 0.02             # a noisy sensor: resuming must restore its generator too
    estimator = dict(learn=learn, restart_every=3 if learn == "all" else "keep")
    if inside:
        estimator["policy"] = dataclasses.replace(scene.defaults.policy, touch_inside=0.02, vision_inside=0.01)
    kw = dict(mode="visual-tactile", max_travel=0.1, metrics_every=100, progress=False,
              settings=EstimatorOverrides(**estimator))
    log = tmp_path / "run.gpioius"
    reference = tg.explore(scene, log=log, **kw)
    assert reference.n_steps > 6
    _cut_after_step(log, 4)
    resumed = tg.explore(scene, resume_from=log, **kw)
    assert resumed.n_steps == reference.n_steps and resumed.terminated == reference.terminated
    assert np.abs(resumed.contacts - reference.contacts).max() < 1e-9
    assert np.abs(resumed.path - reference.path).max() < 1e-9
    # K_t to the Newton run's own tolerance, relative (a learned length can leave K_t's entries near 8)
    scale = max(1.0, float(np.abs(reference.task_covariance).max()))
    assert np.abs(resumed.task_covariance - reference.task_covariance).max() < 1e-9 * scale
    y = reference.model.train_targets
    assert bool((y < 0).any()) == inside and torch.equal(resumed.model.train_targets, y)
    # the length and noise in use: to the bit through step 5, the first resumed one (the log's raw parameters);
    # from step 6 on, learned again from data rebuilt from the log, to the optimiser's rounding
    np.testing.assert_array_equal(resumed.length[:6], reference.length[:6])
    np.testing.assert_array_equal(resumed.noise[:6], reference.noise[:6])
    np.testing.assert_allclose(resumed.length, reference.length, rtol=1e-8)
    np.testing.assert_allclose(resumed.noise, reference.noise, rtol=1e-8)
    if learn == "all":                  # learned at step 3 (and later restarts), kept, and different from the start
        assert reference.length[3] != reference.length[0] and reference.model.hyper_result.kept


@pytest.mark.parametrize("cut", ["after-the-reach", "two-steps-later"])
def test_a_run_that_reached_resumes_to_the_same_end(tmp_path, cut):
    """A reach (lift, route through free space, approach elsewhere) is logged as the evidence action of its step:
    a run cut right after that record, or two steps later, resumes to the uninterrupted run's end, robot and all."""
    from torch_gpioius.exploration import ReachPolicy
    from torch_gpioius.sim import sphere_scene

    scene = sphere_scene(subdivisions=3)
    kw = dict(mode="visual-tactile", evidence=ReachPolicy(min_steps=4), max_travel=0.45, metrics_every=100,
              progress=False)
    log = tmp_path / "run.gpioius"
    reference = tg.explore(scene, log=log, **kw)
    reached = int(np.flatnonzero(np.diff(reference.taps) > 0)[0]) + 1        # the step the first reach followed
    assert reference.n_steps > reached + 3
    # the log holds the whole path, the reach's lift, route and approach included (the viewer draws it from there)
    from torch_gpioius.io.runs import load_run

    np.testing.assert_array_equal(load_run(log).trajectory, reference.path)
    if cut == "after-the-reach":
        end = next(r.end for r in read_records(log) if r.kind == "tap" and r.meta["step"] == reached)
        with open(log, "r+b") as f:
            f.truncate(end)
    else:
        _cut_after_step(log, reached + 2)
    resumed = tg.explore(scene, resume_from=log, **kw)
    assert resumed.n_steps == reference.n_steps and resumed.terminated == reference.terminated
    assert np.abs(resumed.contacts - reference.contacts).max() < 1e-9
    assert np.abs(resumed.path - reference.path).max() < 1e-9
    np.testing.assert_array_equal(resumed.taps, reference.taps)
    assert torch.equal(resumed.model.train_targets, reference.model.train_targets)


def _resumes_alike(scene, log, cut: int, reference, kw: dict) -> None:
    """The log cut after step ``cut`` and resumed ends where the uninterrupted ``reference`` run ended: the same
    steps, contacts, labels and outer mean."""
    _cut_after_step(log, cut)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        resumed = tg.explore(scene, resume_from=log, **kw)
    assert resumed.n_steps == reference.n_steps
    assert np.abs(resumed.contacts - reference.contacts).max() < 1e-9
    assert torch.equal(resumed.model.train_targets, reference.model.train_targets)
    # the mean carried through the learned transfer (cover_carry) reads K_t, which a log restores to its rounding
    assert resumed.model.outer_mean == pytest.approx(reference.model.outer_mean, rel=0, abs=1e-12)


@pytest.mark.parametrize("offset", [False, True], ids=["retracted", "outer-mean"])
def test_a_wide_covers_gap_is_logged_and_resumes_alike(tmp_path, offset):
    """Under a cover 4 cm off an ellipsoid (the defaults for a user's object without the one gap's settings) the
    touches measure the gap once five contacts lie under seen cover and retract the camera's inside points at the first
    step whose contacts put it above ``vision_inside_gap``: the log says which, its replay holds the run's final data.
    With ``cover_offset`` alone the outer task's prior mean is set to 1 - gap / ramp from that step on, logged with each
    step, and the log's model at the last step is the run's; without it the mean stays 1. Either way a run cut before
    that step, or after it, and resumed ends where the uninterrupted one ends.

    The step of the retraction is a chaotic run's (another CPU reaches it a step or two later): the test recomputes
    the rule at every step from the run's own contacts and seen points, and never names the step."""
    import trimesh

    from torch_gpioius.exploration.observations import GAP_MIN_CONTACTS, cover_gap
    from torch_gpioius.io.runs import load_run
    from torch_gpioius.sim.forcefield import Scene3D

    body = trimesh.creation.icosphere(subdivisions=3, radius=0.06)
    body.apply_scale([1.3, 1.0, 0.8])
    scene = Scene3D.from_mesh(body, cover="tight", gap=0.04, at=[0.5, 0.0, 0.1],
                              estimator=tg.EstimatorOverrides(labels={"cover_offset": offset,
                                                                      "vision_inside_deep": False, "cover_even": None}))
    policy = scene.defaults.policy
    assert policy.vision_inside_gap == 0.03 and policy.cover_offset == offset and not policy.vision_inside_deep
    default = Scene3D.from_mesh(body, cover="tight", gap=0.04, at=[0.5, 0.0, 0.1]).defaults.policy
    assert default.cover_offset and default.vision_inside_deep and default.cover_even == 0.25  # one gap while even
    kw = dict(max_travel=0.08, metrics_every=100, progress=False)
    log = tmp_path / "run.gpioius"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        reference = tg.explore(scene, log=log, **kw)
    y, t = reference.model.train_targets.numpy(), reference.model.train_task.numpy()
    run = load_run(log)
    first, last = run.states[run.steps[0]], run.states[run.steps[-1]]
    assert ((first.y < 0) & (first.task == 1)).sum() > 50                 # the camera's, 2 cm behind the cloth
    np.testing.assert_array_equal(last.x, reference.model.train_inputs[0].numpy())
    np.testing.assert_array_equal(last.y, y)
    means = [run.params[k]["outer_mean"] for k in run.steps]
    # the header names cover_offset only when it is on, so that logs written before it existed still resume
    assert run.meta["policy"].get("cover_offset", False) is offset and ("cover_offset" in run.meta["policy"]) is offset

    assert not ((y < 0) & (t == 1)).any()                  # the camera's inside points retracted, with or without
    kept = [((run.states[k].y < 0) & (run.states[k].task == 1)).any() for k in run.steps]
    gone = run.steps.index(next(k for k, inside in zip(run.steps, kept) if not inside))
    assert not any(kept[gone:])                            # once retracted, never added back
    # the rule, recomputed: step k (0: the first contact) judges contacts 0..k under the camera's seen points
    seen = first.x[(first.task == 1) & (first.y == 0)]
    reach = max(0.02, policy.voxel or 0.0)
    gaps = [cover_gap(reference.contacts[:k + 1], seen, reach) for k in run.steps[:gone + 1]]
    assert gone >= GAP_MIN_CONTACTS - 1                    # never before the fifth contact
    assert gaps[gone] > policy.vision_inside_gap and not any(g > policy.vision_inside_gap for g in gaps[:gone])
    if offset:
        assert all(v == 1.0 for v in means[:gone]) and means[gone] == pytest.approx(1.0 - gaps[gone] / policy.ramp)
        assert 0.0 < means[gone] < 0.6 and means[-1] == reference.model.outer_mean
        q = torch.as_tensor(reference.contacts[-3:] * 0.9)
        torch.testing.assert_close(run.model_at(run.steps[-1]).predict(q, 0)[0], reference.model.predict(q, 0)[0],
                                   rtol=0, atol=1e-9)
    else:
        assert set(means) == {1.0}
    assert len(run.steps) > gone + 2, "the run ended before a step after the retraction could be cut"
    for cut in (run.steps[gone - 2], run.steps[gone + 1]):   # before the gap is measured, and after
        _resumes_alike(scene, log, cut, reference, kw)


def test_the_gap_settings_keep_and_deepen_the_cameras_inside_points_and_resume_alike(tmp_path):
    """``settings="gap"`` under a cover 4 cm off an ellipsoid: at the first step whose contacts put the gap above
    ``vision_inside_gap`` the camera's inside points are kept (never retracted) and continued down to the gap, each
    labelled by its depth, once, in that step's batch; the outer mean stands for the gap. The log says so (its header
    names the setting), its replay holds the run's final data, and a run cut after that step and resumed ends where
    the uninterrupted one ends. The step is a chaotic run's: the rule is recomputed from the run's own data."""
    import trimesh

    from torch_gpioius.exploration.observations import GAP_MIN_CONTACTS, cover_gap
    from torch_gpioius.io.runs import load_run
    from torch_gpioius.sim.forcefield import Scene3D

    body = trimesh.creation.icosphere(subdivisions=3, radius=0.06)
    body.apply_scale([1.3, 1.0, 0.8])
    scene = Scene3D.from_mesh(body, cover="tight", gap=0.04, at=[0.5, 0.0, 0.1], settings="gap")
    policy = scene.defaults.policy
    assert policy.cover_offset and policy.vision_inside_deep and policy.vision_inside == 0.02
    kw = dict(max_travel=0.08, metrics_every=100, progress=False)
    log = tmp_path / "run.gpioius"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        reference = tg.explore(scene, log=log, **kw)
    run = load_run(log)
    assert run.meta["policy"]["vision_inside_deep"] is True
    last = run.states[run.steps[-1]]
    np.testing.assert_array_equal(last.x, reference.model.train_inputs[0].numpy())
    np.testing.assert_array_equal(last.y, reference.model.train_targets.numpy())
    camera = [(run.states[k].task == 1) & (run.states[k].y < 0) for k in run.steps]
    assert all(c.sum() >= camera[0].sum() for c in camera)                     # never retracted
    deepest = [float(run.states[k].y[c].min()) for k, c in zip(run.steps, camera)]
    first = policy.inside_label(policy.vision_inside)
    deepened = run.steps.index(next(k for k, d in zip(run.steps, deepest) if d < first - 1e-9))
    seen = run.states[run.steps[0]].x[(run.states[run.steps[0]].task == 1) & (run.states[run.steps[0]].y == 0)]
    gap = cover_gap(reference.contacts[:deepened + 1], seen, max(0.02, policy.voxel or 0.0))
    assert gap > policy.vision_inside_gap
    assert -deepest[deepened] * policy.ramp <= gap + policy.vision_inside + 1e-9           # down to the gap
    added = camera[deepened].sum() - camera[deepened - 1].sum()
    assert added > 0 and all(c.sum() == camera[deepened].sum() for c in camera[deepened:])  # once
    assert run.params[run.steps[deepened]]["outer_mean"] < 1.0
    assert deepened >= GAP_MIN_CONTACTS - 1                                  # never before the fifth contact
    _resumes_alike(scene, log, run.steps[min(deepened + 1, len(run.steps) - 2)], reference, kw)


def test_a_miscalibrated_cameras_captures_are_corrected_logged_and_resume_alike(tmp_path):
    """Issue 63, item 2: with ``ObservationPolicy.camera_bound`` a run whose simulated cameras are off by 6 mm and a
    degree corrects each view's capture from its first :data:`CORRECT_AFTER` contacts, and again every
    :data:`CORRECT_EVERY` more, replacing the camera's observations by the corrected ones in that step's batch: the
    error at the body's middle falls, the step's record says what each view was moved by, the log replays the run's
    final data, and a run cut before the first correction, or between two, and resumed ends where the uninterrupted
    one ends."""
    import dataclasses
    import math

    import trimesh

    from torch_gpioius.exploration.calibration import CORRECT_AFTER, CORRECT_EVERY
    from torch_gpioius.io.datasets import read_records
    from torch_gpioius.io.runs import load_run
    from torch_gpioius.sim.forcefield import Scene3D

    body = trimesh.creation.box((0.10, 0.08, 0.12))
    scene = Scene3D.from_mesh(body, cover="tight", at=[0.5, 0.0, 0.1]).with_camera_error("6mm,1deg")
    policy = dataclasses.replace(scene.defaults.policy, camera_bound=(0.012, math.radians(2)))
    kw = dict(max_steps=CORRECT_AFTER + CORRECT_EVERY + 4, metrics_every=100, progress=False, policy=policy)
    log = tmp_path / "run.gpioius"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        reference = tg.explore(scene, log=log, **kw)
    run = load_run(log)
    assert run.meta["policy"]["camera_bound"] == [0.012, pytest.approx(math.radians(2))]
    assert run.meta["policy"]["camera_table"] is True              # the views of the table held to it as well
    steps = [r for r in read_records(log) if r.kind == "step"]
    marked = [int(r.meta["step"]) for r in steps if "camera_corrections" in r.meta]
    # before the first touch from the table alone (step 0), then at the steps of the 20th and 40th contacts
    assert marked == [0, CORRECT_AFTER - 1, CORRECT_AFTER + CORRECT_EVERY - 1]
    at_start = steps[0].meta["camera_corrections"]["captures"]
    assert all(c["contacts"] == 0 and c["support"] >= 100 for c in at_start)
    corrections = reference.camera_corrections
    assert corrections == steps[marked[-1]].meta["camera_corrections"] and len(corrections["captures"]) == 3
    assert all(c["size_mm"] <= 12.0 + 1e-9 for c in corrections["captures"])
    assert all(c.get("support", 0) > 50 for c in corrections["captures"])   # each view's table took part

    # each view's error at the body's middle, as applied and once corrected (1.5-2.5 cm -> a few mm)
    from torch_gpioius.sensors.extrinsics import CaptureCorrection
    from torch_gpioius.sensors.simulated.camera import AppliedCameraError

    middle = scene.inner.bounds.mean(axis=0)
    before, left = [], []
    for (name, applied), fix in zip(scene.camera_errors().items(), corrections["captures"]):
        error = AppliedCameraError(tuple(np.asarray(applied["translation_mm"]) / 1e3),
                                   tuple(np.radians(applied["rotation_deg"])))
        seen = error.apply(middle[None], fix["origin"])
        before.append(np.linalg.norm(seen[0] - middle))
        left.append(np.linalg.norm(CaptureCorrection.from_record(fix).apply(seen)[0] - middle))
    assert sum(left) < 0.5 * sum(before) and max(left) < 0.012, (before, left)
    first = []                                       # the table alone, before any touch, already took most of it
    for (name, applied), fix in zip(scene.camera_errors().items(), at_start):
        error = AppliedCameraError(tuple(np.asarray(applied["translation_mm"]) / 1e3),
                                   tuple(np.radians(applied["rotation_deg"])))
        first.append(np.linalg.norm(CaptureCorrection.from_record(fix).apply(error.apply(middle[None],
                                                                                     fix["origin"]))[0] - middle))
    assert sum(first) < 0.75 * sum(before), (before, first)
    last = run.states[run.steps[-1]]
    np.testing.assert_array_equal(last.x, reference.model.train_inputs[0].numpy())
    np.testing.assert_array_equal(last.y, reference.model.train_targets.numpy())
    for cut in (marked[1] - 3, marked[1] + 2):       # before and after the first correction from the contacts
        _resumes_alike(scene, log, cut, reference, kw)


def test_the_gap_field_settings_log_the_field_and_resume_alike(tmp_path):
    """``settings="gapfield"`` under a cover 4 cm off an ellipsoid: once the field of the contacts' gaps exceeds the
    3 cm limit the outer mean is that field (logged with each step: the replay's model at the last step predicts as
    the run's does), the camera's inside points are continued down to it, and a run cut after that step and resumed
    ends where the uninterrupted one ends, with the same field. The step is a chaotic run's: found from the log."""
    import trimesh

    from torch_gpioius.io.runs import load_run
    from torch_gpioius.sim.forcefield import Scene3D

    body = trimesh.creation.icosphere(subdivisions=3, radius=0.06)
    body.apply_scale([1.3, 1.0, 0.8])
    scene = Scene3D.from_mesh(body, cover="tight", gap=0.04, at=[0.5, 0.0, 0.1], settings="gapfield")
    assert scene.defaults.policy.cover_gap_field
    kw = dict(max_travel=0.08, metrics_every=100, progress=False)
    log = tmp_path / "run.gpioius"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        reference = tg.explore(scene, log=log, **kw)
    field = reference.model.outer_field
    assert field is not None and field.gap(reference.contacts).min() > 0.02      # it stands for the 4 cm cover
    run = load_run(log)
    assert run.meta["policy"]["cover_gap_field"] is True
    fielded = [k for k in run.steps if "outer_field" in run.params[k]]
    assert fielded and run.params[run.steps[-1]]["outer_field"] == field
    last = run.model_at(run.steps[-1])
    q = torch.as_tensor(reference.contacts[::3])
    torch.testing.assert_close(last.predict(q, 0)[0], reference.model.predict(q, 0)[0], rtol=0, atol=1e-9)
    first = scene.defaults.policy.inside_label(scene.defaults.policy.vision_inside)
    state = run.states[fielded[0]]
    assert ((state.task == 1) & (state.y < first - 1e-9)).any()                  # continued down to it
    _resumes_alike(scene, log, run.steps[min(run.steps.index(fielded[0]) + 1, len(run.steps) - 2)], reference, kw)
    resumed = load_run(log)
    again = resumed.params[resumed.steps[-1]]["outer_field"]
    # the field's carry through the learned transfer (cover_carry) reads K_t, which a log restores to its rounding
    assert abs(again.carry - field.carry) < 1e-12 and again.carried(field.carry) == field



def _logged_run(scene, log, travel):
    """``(trace, x, y, task)``: a short run of ``scene`` logged to ``log``, and its final data as arrays."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        trace = tg.explore(scene, log=log, max_travel=travel, metrics_every=100, progress=False)
    m = trace.model
    return (trace, *(v.numpy() for v in (m.train_inputs[0], m.train_targets, m.train_task)))

def test_repeated_contacts_are_in_the_model_k_times_in_the_header_and_replayed_from_the_log(tmp_path):
    """``contact_repeats`` in the loop: every contact row of the model three times (its inside and free points once),
    the header names the setting only when it is set, and the log's replay holds the same model."""
    import trimesh

    from torch_gpioius.io.runs import load_run
    from torch_gpioius.sim.forcefield import Scene3D

    body = trimesh.creation.icosphere(subdivisions=3, radius=0.06)
    scene = Scene3D.from_mesh(body, cover="tight", at=[0.5, 0.0, 0.1],
                              estimator=tg.EstimatorOverrides(labels={"contact_repeats": 3}))
    assert scene.defaults.policy.contact_repeats == 3
    log = tmp_path / "run.gpioius"
    reference, x, y, t = _logged_run(scene, log, 0.06)
    surface = x[(t == 0) & (y == 0)]
    assert len(surface) == 3 * len(reference.contacts)
    for contact in reference.contacts:
        assert (np.abs(surface - contact).max(axis=1) == 0).sum() == 3
    run = load_run(log)
    assert run.meta["policy"]["contact_repeats"] == 3
    q = torch.as_tensor(np.asarray(reference.contacts[-2:]) * 0.9)
    torch.testing.assert_close(run.model_at(run.steps[-1]).predict(q, 0)[0], reference.model.predict(q, 0)[0],
                               rtol=0, atol=1e-9)
    # the paper's one noise: not in the header, so that logs written before the setting existed still resume
    one = tmp_path / "one.gpioius"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        tg.explore(scene.with_estimator(tg.EstimatorOverrides(labels={"contact_repeats": 1})), log=one,
                   max_travel=0.02, metrics_every=100, progress=False)
    assert "contact_repeats" not in load_run(one).meta["policy"]


def test_a_thin_bodys_inside_points_halved_in_the_loop_lie_inside_and_are_replayed_from_the_log(tmp_path):
    """``inside_halvings`` in the loop, on a fin 1.2 cm thick (2.8 cm with its tight cover) seen from both sides: the
    camera's 2 cm points behind its faces are contradicted by the far faces, and with halvings the model holds
    points 1 cm (or 5 mm) deep, labelled by that depth, nearly all inside the cover (measured: all); the header
    names the setting, and the log's replay holds the same model. Without it the model holds none at those depths."""
    import trimesh

    from torch_gpioius.io.runs import load_run
    from torch_gpioius.sim.forcefield import Scene3D
    from torch_gpioius.sim.meshes import MeshDistance

    fin = trimesh.creation.box(extents=[0.16, 0.012, 0.10])
    scene = Scene3D.from_mesh(fin, cover="tight", at=[0.5, 0.0, 0.1],
                              estimator=tg.EstimatorOverrides(labels={"inside_halvings": 2}))
    policy = scene.defaults.policy
    assert policy.inside_halvings == 2
    shallow = np.round([policy.inside_label(0.01), policy.inside_label(0.005)], 12)
    log = tmp_path / "run.gpioius"
    reference, x, y, t = _logged_run(scene, log, 0.04)
    halved = np.isin(np.round(y, 12), shallow) & (t == 1)
    assert halved.sum() > 10
    assert (-MeshDistance(scene.outer)(x[halved]) > 0).mean() > 0.9                # inside the cover's surface
    run = load_run(log)
    assert run.meta["policy"]["inside_halvings"] == 2
    q = torch.as_tensor(np.asarray(reference.contacts[-2:]) * 0.9)
    torch.testing.assert_close(run.model_at(run.steps[-1]).predict(q, 0)[0], reference.model.predict(q, 0)[0],
                               rtol=0, atol=1e-9)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        without = tg.explore(Scene3D.from_mesh(fin, cover="tight", at=[0.5, 0.0, 0.1],
                                               estimator=tg.EstimatorOverrides(labels={"inside_halvings": 0})),
                             max_travel=0.01,
                             metrics_every=100, progress=False)
    assert not np.isin(np.round(without.model.train_targets.numpy(), 12), shallow).any()
