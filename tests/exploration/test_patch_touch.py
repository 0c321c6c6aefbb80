"""touch="patch": a simulated gel pad explores a 3-D object; its points are on the body (plus the cloth)."""

import numpy as np
import pytest

import torch_gpioius as tg
from torch_gpioius.exploration.registry import make_world
from torch_gpioius.exploration.touch import PatchTouch
from torch_gpioius.io.datasets import replay


@pytest.mark.parametrize("mode", ["visual-tactile", "tactile"])
def test_a_simulated_pad_explores_the_arm_and_its_patches_lie_on_the_body(mode, tmp_path):
    world = make_world("forcefield", "E", 0, smoke=True)
    log = tmp_path / "run.gpioius"
    trace = tg.explore(world, mode, touch="patch", max_travel=0.03, metrics_every=100, log=log)
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
    from torch_gpioius.io.datasets import read_records
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
