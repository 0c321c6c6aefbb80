"""The simple baselines scored beside the method (torch_gpioius.baselines), on a sphere under a uniform cover whose
answers are known: the camera's surface stands 1 cm off the body, the gap the touches measure is that centimetre, and
the vision surface shrunk by it is the body."""

import math

import numpy as np
import pytest
from torch_gpioius.baselines import BASELINES, BaselineData, BaselineEstimate, register_baseline, score_baselines
from torch_gpioius.kernels import Matern52
from torch_gpioius.sim.forcefield import sphere_scene


def _data(world, contacts: int = 30, seed: int = 0) -> BaselineData:
    rng = np.random.default_rng(seed)
    c = world.inner.bounds.mean(axis=0)
    d = rng.standard_normal((900, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    d = d[d[:, 2] > -0.3]                                        # what cameras above the table see
    seen, free = c + 0.07 * d, c + 0.12 * d
    t = rng.standard_normal((contacts, 3))
    t /= np.linalg.norm(t, axis=1, keepdims=True)
    t[:, 2] = np.abs(t[:, 2])
    return BaselineData(np.concatenate([seen, free]), np.r_[np.zeros(len(seen)), np.ones(len(free))],
                        c + 0.06 * t, Matern52(0.04), 1e-3, world.bounds(0.05))


def test_the_vision_baseline_is_the_cover_and_the_shrunk_ones_find_the_body_by_the_touches_gap():
    world = sphere_scene(radius=0.06, cover=0.01, subdivisions=5)
    scores = score_baselines(world, _data(world), np.zeros((0, 3)))
    assert set(scores) >= {"vision", "vision-shrunk-5", "vision-shrunk-all"}
    vision, first5, every = scores["vision"], scores["vision-shrunk-5"], scores["vision-shrunk-all"]
    # the camera's surface lies on the 7 cm cover: 1 cm from the 6 cm body everywhere it was seen, outside it
    assert 0.008 < vision["chamfer"] < 0.012 and vision["bias"] > 0.008 and vision["fscore_5mm"] < 0.1
    assert math.isnan(vision["gap"])
    for shrunk in (first5, every):
        assert shrunk["gap"] == pytest.approx(0.01, abs=0.002)          # the touches' depth under the cover
        assert shrunk["chamfer"] < 0.3 * vision["chamfer"] and abs(shrunk["bias"]) < 0.002
        assert shrunk["fscore_5mm"] > 0.9


def test_a_users_baseline_is_one_function_and_one_registration_and_no_estimate_scores_as_the_worst():
    world = sphere_scene(radius=0.06, cover=0.01, subdivisions=5)
    truth = world.inner.copy()

    def exact(data):
        centre = truth.bounds.mean(axis=0)
        return BaselineEstimate(truth, lambda p: np.linalg.norm(p - centre, axis=1) < 0.06)

    register_baseline("exact-for-test", exact, description="the body itself")
    register_baseline("nothing-for-test", lambda data: None)
    try:
        scores = score_baselines(world, _data(world), np.zeros((0, 3)), names=["exact-for-test", "nothing-for-test"])
    finally:
        for name in ("exact-for-test", "nothing-for-test"):
            BASELINES._entries.pop(name)
    assert scores["exact-for-test"]["chamfer"] < 1e-4 and scores["exact-for-test"]["fscore_5mm"] > 0.999
    assert scores["nothing-for-test"]["chamfer"] == math.inf and scores["nothing-for-test"]["fscore_5mm"] == 0.0
    with pytest.raises(ValueError, match="already"):
        register_baseline("vision", exact)


def test_the_plain_baselines_shrink_the_capture_labelled_without_the_smoothing_and_equal_the_others_without_it():
    """``vision-shrunk-*-plain`` use :attr:`BaselineData.plain` (here the seen cover labelled 5 mm further out, as
    another labelling of the same capture would place it): their gap is measured against that surface (1.5 cm) and
    they still find the body; without a plain form they are the baselines above, to the digit."""
    world = sphere_scene(radius=0.06, cover=0.01, subdivisions=5)
    data = _data(world)
    seen = data.outer_y == 0
    c = world.inner.bounds.mean(axis=0)
    x = data.outer_x.copy()
    x[seen] = c + (x[seen] - c) * (0.075 / 0.07)
    names = ["vision-shrunk-5", "vision-shrunk-5-plain", "vision-shrunk-all-plain"]
    scores = score_baselines(world, BaselineData(data.outer_x, data.outer_y, data.contacts, data.kernel, data.noise,
                                                 data.bounds, plain=(x, data.outer_y)), np.zeros((0, 3)), names)
    assert scores["vision-shrunk-5"]["gap"] == pytest.approx(0.01, abs=0.002)
    for name in names[1:]:
        assert scores[name]["gap"] == pytest.approx(0.015, abs=0.002)
        assert abs(scores[name]["bias"]) < 0.002 and scores[name]["fscore_5mm"] > 0.9
    alone = score_baselines(world, _data(world), np.zeros((0, 3)), ["vision-shrunk-5", "vision-shrunk-5-plain"])
    assert alone["vision-shrunk-5-plain"] == alone["vision-shrunk-5"]


def test_a_smoothing_run_keeps_its_capture_as_the_paper_labels_it_for_the_baselines():
    """The plain form a run with the ray smoothing keeps is what a run without it labels from the same capture."""
    import torch_gpioius as tg
    from torch_gpioius.models.overrides import EstimatorOverrides
    from torch_gpioius.sim.objectsets import object_set, set_scene

    world = set_scene(next(iter(object_set("primitives:3"))), "tight", seed=0)
    smooth = tg.explore(world, max_steps=1, metrics_every=1000)
    plain = tg.explore(world, max_steps=1, metrics_every=1000,
                       settings=EstimatorOverrides(labels={"ray_smoothing": None}))
    assert world.defaults.policy.ray_smoothing and plain.vision_plain is None
    x, y = smooth.vision_plain
    task = plain.model._train_task().numpy()
    np.testing.assert_array_equal(x, plain.model.train_inputs[0].numpy()[task == 1][:len(x)])
    np.testing.assert_array_equal(y, plain.model.train_targets.numpy()[task == 1][:len(y)])
    assert (task == 1).sum() == len(x)                       # the capture's observations, nothing retracted yet
    seen = smooth.model.train_targets.numpy()[smooth.model._train_task().numpy() == 1] == 0
    assert seen.sum() != (y == 0).sum()                      # the smoothing chose other voxels
