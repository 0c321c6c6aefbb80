"""The observation model's inside points: labels below zero, where a touch and a camera put them, and their checks."""

import dataclasses
from types import SimpleNamespace

import numpy as np
import pytest
import shapely.geometry
import torch

import torch_gpioius as tg
from torch_gpioius.core.validation import as_labels
from torch_gpioius.exploration.observations import ObservationPolicy, Observations, vision_observations
from torch_gpioius.exploration.touch import PointTouch

from tests.gaps import gaps_by_hand
from torch_gpioius.sim.plane import PlanarView
from torch_gpioius.models.overrides import EstimatorOverrides


def test_labels_below_zero_mean_inside_and_everything_else_is_still_refused():
    ok = [0.0, 1.0, -0.4, -1.0, -3.0]
    assert as_labels(torch.tensor(ok, dtype=torch.float64), 5).tolist() == ok
    Observations(np.zeros((5, 3)), ok, np.zeros(5, int))
    tg.GPIOIS(
        torch.rand(5, 3, dtype=torch.float64), torch.tensor(ok, dtype=torch.float64), torch.zeros(5, dtype=torch.long)
    )
    for bad, shown in ((0.5, "0.5"), (2.0, "2.0"), (float("-inf"), "-inf"), (float("nan"), "nan")):
        with pytest.raises(
            ValueError, match=f"labels must be 0 \\(surface\\), 1 \\(free space\\) or negative.*{shown}"
        ):
            Observations(np.zeros((2, 3)), [0.0, bad], [0, 0])
        with pytest.raises(ValueError, match="labels"):
            as_labels(torch.tensor([0.0, bad]), 2)


def test_the_inside_label_continues_the_free_space_ramp_inside():
    assert ObservationPolicy().inside_label(0.02) == pytest.approx(-0.4)                # 1 at 5 cm out, 0 on it
    assert ObservationPolicy(vision_free_offset=0.04).inside_label(0.02) == pytest.approx(-0.5)
    assert ObservationPolicy(vision_free_offset=None).inside_label(0.05) == pytest.approx(-1.0)
    for name in ("touch_inside", "vision_inside"):
        with pytest.raises(ValueError, match=name):
            ObservationPolicy(**{name: -0.02})
        with pytest.raises(ValueError, match=name):
            ObservationPolicy(**{name: float("nan")})


def _touch(contact, force, free):
    forces = torch.as_tensor(np.atleast_2d(force), dtype=torch.float64)
    return SimpleNamespace(forces=forces, force_normal=forces[-1] / forces[-1].norm().clamp_min(1e-12),
                           free_space=torch.as_tensor(free, dtype=torch.float64).reshape(-1, len(contact)))


def test_a_point_touch_puts_its_inside_point_behind_the_contact_along_the_measured_force():
    contact = np.array([0.3, 0.1, 0.2])
    force = np.array([0.0, 3.0, 4.0])                            # 5 N, outward unit normal (0, 0.6, 0.8)
    free = contact + np.outer(np.linspace(0.03, 0.09, 4), [0.0, 0.6, 0.8])
    policy = ObservationPolicy(touch_inside=0.02)
    obs = PointTouch().observations(_touch(contact, force, free), contact[None], policy, step=3)
    np.testing.assert_allclose(obs.x[0], contact)
    np.testing.assert_allclose(obs.x[1], contact - 0.02 * np.array([0.0, 0.6, 0.8]), atol=1e-15)
    assert (
        obs.y.tolist() == pytest.approx([0.0, -0.4, 1.0, 1.0, 1.0, 1.0], abs=1e-15)
        and (obs.task == 0).all()
        and obs.step == 3
    )
    # the paper's observations: no inside point; nor without a measured force to give the normal
    assert (PointTouch().observations(_touch(contact, force, free), contact[None], ObservationPolicy(), 3).y >= 0).all()
    silent = PointTouch().observations(_touch(contact, np.zeros(3), free), contact[None], policy, 3)
    assert (silent.y >= 0).all() and len(silent) == 5


def test_a_camera_puts_its_inside_points_behind_the_seen_outline_in_2d():
    disc = shapely.geometry.Point(0.0, 0.0).buffer(0.1, 256)
    view = PlanarView(np.array(disc.exterior.coords)[:-1], origin=None, polygon=disc, spacing=0.01)
    policy = ObservationPolicy(vision_inside=0.03)
    x, y = vision_observations(view, policy)
    inside = x[y < 0]
    assert len(inside) and np.allclose(y[y < 0], policy.inside_label(0.03))
    np.testing.assert_allclose(np.linalg.norm(inside, axis=1), 0.07, atol=1e-4)     # the disc shrunk by 3 cm
    assert len(vision_observations(view, ObservationPolicy())[1]) == (y >= 0).sum()  # the rest unchanged
    # thinner than twice the depth: no inside point, rather than one outside the body
    sliver = shapely.geometry.box(0.0, 0.0, 0.2, 0.04)
    assert len(PlanarView(np.array(sliver.exterior.coords)[:-1], polygon=sliver).behind(0.03)) == 0


def test_inside_points_of_an_exploration_lie_inside_the_true_bodies():
    """A short visual-tactile run on a duck under a tight cover (three views): every touch's inside point lies in the
    body, and the camera's lie in the cover (the force's direction and the cloud's normals both point out) but for the
    few behind parts thinner than the depth (the assumption :meth:`PointCloud.behind` states)."""
    from torch_gpioius.sim.meshes import MeshDistance
    from torch_gpioius.sim.scenefile import load_scene

    scene = load_scene("examples/scenes/real/duck-tight.toml")
    policy = dataclasses.replace(scene.defaults.policy, touch_inside=0.02, vision_inside=0.02)
    trace = tg.explore(scene, max_travel=0.05, metrics_every=1000, settings=EstimatorOverrides(policy=policy))
    x, y, t = (v.numpy() for v in (trace.model.train_inputs[0], trace.model.train_targets, trace.model.train_task))
    touch_in, seen_in = (y < 0) & (t == 0), (y < 0) & (t == 1)
    assert touch_in.sum() == len(np.unique(x[(y == 0) & (t == 0)], axis=0))  # one per contact
    assert seen_in.sum() > 50
    depth_in = -MeshDistance(scene.inner)(x[touch_in])
    depth_out = -MeshDistance(scene.outer)(x[seen_in])
    # 2 cm behind a contact pressed up to a few mm into the body, along a normal a few degrees off the mesh's
    assert depth_in.min() > 0.012 and np.median(depth_in) == pytest.approx(0.02, abs=0.004)
    # behind noisy points along plane fits, then voxel-averaged: all but a few inside (measured: 0.2 % of the raw
    # points' fall outside, at the beak), most near the depth
    assert (depth_out > 0).mean() > 0.97 and np.median(depth_out) == pytest.approx(0.02, abs=0.005)


def test_an_inside_point_that_other_observations_contradict_is_dropped():
    """A slab 1.5 cm thick seen from both sides: 2 cm behind one face lies beyond the other face, so that point goes;
    on a block 10 cm thick it stays; free space closer than the depth also removes it."""
    from torch_gpioius.exploration.observations import drop_contradicted_inside

    policy = ObservationPolicy(touch_inside=0.02)
    grid = np.stack(np.meshgrid(np.linspace(-0.05, 0.05, 6), np.linspace(-0.05, 0.05, 6)), -1).reshape(-1, 2)
    face = lambda z: np.c_[grid, np.full(len(grid), z)]                              # noqa: E731
    touch = Observations(np.array([[0.0, 0.0, 0.0], [0.0, 0.0, -0.02]]), [0.0, policy.inside_label(0.02)], [0, 0])
    thin = drop_contradicted_inside(touch, policy, face(-0.015), np.zeros(len(grid)))
    assert thin.y.tolist() == [0.0]                                                  # the far face 5 mm from it
    thick = drop_contradicted_inside(touch, policy, np.r_[face(0.0), face(-0.10)], np.zeros(2 * len(grid)))
    assert len(thick) == 2 and thick.y[1] < 0                                        # its own face at the full depth
    near = drop_contradicted_inside(touch, policy, np.array([[0.0, 0.015, -0.02]]), np.ones(1))
    assert near.y.tolist() == [0.0]                                                  # free space 1.5 cm from it
    far = drop_contradicted_inside(touch, policy, np.array([[0.0, 0.03, -0.02]]), np.ones(1))
    assert len(far) == 2                                                             # 3 cm: beyond its depth



def test_a_touchs_contradicted_inside_point_is_tried_again_up_its_line_with_halvings():
    """The 1.5 cm slab again, with ``inside_halvings``: the contact's 2 cm point is tried 1 cm behind it (5 mm from
    the far face, within 0.9 of that depth: contradicted too) and then 5 mm behind it (1 cm from the far face), where
    it stays, the same row relabelled by that depth; with one halving only, it goes. Free space 1.5 cm
    from the 2 cm point leaves the 1 cm one (1.8 cm from it) standing. The same check by step, as a contacts file is
    labelled, moves the same point. A batch whose inside point has no surface point of its own is dropped as before."""
    from torch_gpioius.exploration.observations import drop_contradicted_inside, inside_checked_by_step

    policy = ObservationPolicy(touch_inside=0.02, inside_halvings=2)
    grid = np.stack(np.meshgrid(np.linspace(-0.05, 0.05, 11), np.linspace(-0.05, 0.05, 11)), -1).reshape(-1, 2)
    far_face = np.c_[grid, np.full(len(grid), -0.015)]
    touch = Observations(np.array([[0.0, 0.0, 0.0], [0.0, 0.0, -0.02]]), [0.0, policy.inside_label(0.02)], [0, 0])
    thin = drop_contradicted_inside(touch, policy, far_face, np.zeros(len(grid)))
    assert len(thin) == 2
    np.testing.assert_allclose(thin.x[1], [0.0, 0.0, -0.005], atol=1e-15)
    assert thin.y[1] == policy.inside_label(0.005)
    once = drop_contradicted_inside(touch, dataclasses.replace(policy, inside_halvings=1), far_face,
                                    np.zeros(len(grid)))
    assert once.y.tolist() == [0.0]
    near = drop_contradicted_inside(touch, policy, np.array([[0.0, 0.015, -0.02]]), np.ones(1))
    np.testing.assert_allclose(near.x[1], [0.0, 0.0, -0.01], atol=1e-15)
    x, y, keep = inside_checked_by_step(touch.x, touch.y, np.array([1, 1]), policy, far_face, np.zeros(len(grid)))
    assert keep.all() and np.allclose(x, thin.x) and np.allclose(y, thin.y)
    orphan = Observations(np.array([[0.0, 0.0, -0.02]]), [policy.inside_label(0.02)], [0])
    assert len(drop_contradicted_inside(orphan, policy, far_face, np.zeros(len(grid)))) == 0


def _sphere(radius, n, seed=0):
    v = np.random.default_rng(seed).normal(size=(n, 3))
    return radius * v / np.linalg.norm(v, axis=1, keepdims=True)


def test_the_covers_gap_is_the_contacts_median_distance_to_the_seen_cover():
    """Contacts on a sphere of 10 cm, the cover seen on one of 14 cm, sparsely (300 points, 3 cm apart, as voxel
    means are): 4 cm along the local planes, less their sagitta (a plane through points up to 4 cm apart on a 14 cm
    sphere cuts up to r^2 / 2R = 6 mm into it; 2-3 mm at the median); contacts under a part the camera did not see
    do not count, and fewer than five that count give NaN."""
    from torch_gpioius.exploration.observations import GAP_MIN_CONTACTS, cover_gap

    contacts, seen = _sphere(0.10, 40, seed=1), _sphere(0.14, 300, seed=2)
    assert 0.034 < cover_gap(contacts, seen) < 0.04
    half = seen[seen[:, 2] > 0]                                                   # the camera saw the upper half
    below = contacts[contacts[:, 2] < -0.05]
    assert len(below) >= GAP_MIN_CONTACTS and np.isnan(cover_gap(below, half))
    assert 0.034 < cover_gap(np.r_[below, contacts[contacts[:, 2] > 0.03]], half) < 0.04
    assert np.isnan(cover_gap(contacts[:GAP_MIN_CONTACTS - 1], seen))
    assert np.isnan(cover_gap(np.zeros((0, 3)), seen)) and np.isnan(cover_gap(contacts, np.zeros((0, 3))))


def _gap_by_hand(contacts, seen, reach, neighbours=6):
    """The cover's gap recomputed contact by contact (tests.gaps), the median of five or more."""
    counted = gaps_by_hand(contacts, seen, reach, neighbours)
    return float(np.median(counted)) if len(counted) >= 5 else float("nan")


def test_a_runs_gap_check_computes_each_contact_once_and_equals_the_whole_computation():
    """CoverGap, asked at every step with one contact more, equals cover_gap on all the contacts exactly, and a
    by-hand computation to rounding; when the seen points change (the camera's data retracted, a second capture) or
    the contacts are not the earlier ones plus new ones (a resumed run, another run) it starts over."""
    from torch_gpioius.exploration.observations import CoverGap, cover_gap

    contacts, seen = _sphere(0.10, 30, seed=7), _sphere(0.13, 300, seed=8)
    check = CoverGap()
    for n in range(1, len(contacts) + 1):
        value = check(contacts[:n], seen, 0.02)
        ref = cover_gap(contacts[:n], seen, 0.02)
        assert value == ref or (np.isnan(value) and np.isnan(ref))
    assert check._along.shape == (len(contacts),)                  # each contact's plane computed once
    assert abs(value - _gap_by_hand(contacts, seen, 0.02)) < 1e-12
    assert 0.02 < value < 0.03
    fewer = seen[seen[:, 2] > -0.05]                                # the seen points change: computed afresh
    assert check(contacts, fewer, 0.02) == cover_gap(contacts, fewer, 0.02)
    assert abs(check(contacts, fewer, 0.02) - _gap_by_hand(contacts, fewer, 0.02)) < 1e-12
    other = _sphere(0.11, 30, seed=9)                                # other contacts: not mistaken for the earlier
    assert check(other, fewer, 0.02) == cover_gap(other, fewer, 0.02)
    assert check(contacts[:20], fewer, 0.05) == cover_gap(contacts[:20], fewer, 0.05)
    with pytest.raises(ValueError, match="neighbours"):
        CoverGap(2)


@pytest.mark.parametrize("cover", [0.008, 0.04], ids=["tight", "wide"])
def test_the_cameras_inside_points_go_once_the_touches_show_a_cover_standing_off(cover):
    """A body of 10 cm radius under a cover ``cover`` off it: the camera's inside points (2 cm behind the seen cover)
    lie in the body under the tight cover and in the gap under the wide one. With a 2 cm limit the wide cover's are
    removed, all of them and nothing else, once five contacts are in; never the tight one's, nor without a limit."""
    from torch_gpioius.exploration.observations import GAP_MIN_CONTACTS, retract_vision_inside

    policy = ObservationPolicy(vision_inside=0.02, vision_inside_gap=0.02)
    seen = _sphere(0.10 + cover, 300, seed=4)
    inside = seen * (1.0 - 0.02 / (0.10 + cover))
    contacts = _sphere(0.10, 12, seed=5)
    x = np.r_[contacts, seen, inside]
    y = np.r_[np.zeros(len(contacts) + len(seen)), np.full(len(inside), policy.inside_label(0.02))]
    t = np.r_[np.zeros(len(contacts)), np.ones(len(seen) + len(inside))].astype(np.int64)

    m = tg.GPIOIS(
        torch.as_tensor(x), torch.as_tensor(y), torch.as_tensor(t), kernel=tg.kernels.InverseMultiquadricKernel(0.1)
    )
    assert len(retract_vision_inside(m, contacts[:GAP_MIN_CONTACTS - 1], policy)) == 0
    assert len(m.train_targets) == len(x)
    assert len(retract_vision_inside(m, contacts, dataclasses.replace(policy, vision_inside_gap=None))) == 0
    removed = retract_vision_inside(m, contacts, policy)


    if cover < 0.02:
        assert len(removed) == 0 and len(m.train_targets) == len(x)
        return
    np.testing.assert_array_equal(removed, np.flatnonzero(y < 0))
    np.testing.assert_array_equal(m.train_inputs[0].numpy(), x[y >= 0])
    np.testing.assert_array_equal(m.train_task.numpy(), t[y >= 0])
    # the model after the removal equals one built without them (its engine rebuilt, not patched)
    ref = tg.GPIOIS(
        torch.as_tensor(x[y >= 0]),
        torch.as_tensor(y[y >= 0]),
        torch.as_tensor(t[y >= 0]),
        kernel=tg.kernels.InverseMultiquadricKernel(0.1),
    )
    q = torch.as_tensor(_sphere(0.12, 20, seed=6))
    torch.testing.assert_close(m.predict(q)[0], ref.predict(q)[0], rtol=0, atol=1e-10)
    assert len(retract_vision_inside(m, contacts, policy)) == 0               # nothing left to remove


def test_the_policy_refuses_a_gap_that_is_not_a_length():
    for bad in (-0.02, 0.0, float("nan"), True):
        with pytest.raises(ValueError, match="vision_inside_gap"):
            ObservationPolicy(vision_inside_gap=bad)


@pytest.mark.parametrize("cover", [0.008, 0.04], ids=["tight", "wide"])
def test_the_outer_mean_stands_for_the_gap_the_touches_measure(cover):
    """The same body and covers: with ``cover_offset`` the wide cover's gap (4 cm less the planes' sagitta) sets the
    outer task's prior mean to 1 - gap / ramp once five contacts are in; the tight cover's (under the 2 cm limit)
    leaves it at 1, as do no limit, no ``cover_offset``, or fewer contacts; a gap that moves by no more than
    OFFSET_STEP leaves it where it was, one that moves further moves it."""
    from torch_gpioius.exploration.observations import (GAP_MIN_CONTACTS, OFFSET_STEP, cover_gap,
                                                        offset_outer_mean)

    policy = ObservationPolicy(vision_inside=0.02, vision_inside_gap=0.02, cover_offset=True)
    seen = _sphere(0.10 + cover, 300, seed=4)
    contacts = _sphere(0.10, 12, seed=5)
    x, y = np.r_[contacts, seen], np.zeros(len(contacts) + len(seen))
    t = np.r_[np.zeros(len(contacts)), np.ones(len(seen))].astype(np.int64)
    m = tg.GPIOIS(
        torch.as_tensor(x), torch.as_tensor(y), torch.as_tensor(t), kernel=tg.kernels.InverseMultiquadricKernel(0.1)
    )
    assert not offset_outer_mean(m, contacts[:GAP_MIN_CONTACTS - 1], policy)
    assert not offset_outer_mean(m, contacts, dataclasses.replace(policy, cover_offset=False))
    assert not offset_outer_mean(m, contacts, dataclasses.replace(policy, vision_inside_gap=None))
    assert m.outer_mean == 1.0
    changed = offset_outer_mean(m, contacts, policy)
    gap = cover_gap(contacts, seen, reach=0.02)
    if cover < 0.02:
        assert not changed and m.outer_mean == 1.0
        return
    assert changed and 0.034 < gap < 0.04
    assert abs(m.outer_mean - (1.0 - gap / policy.ramp)) < 1e-15
    # the touches move on: within OFFSET_STEP the mean stays, beyond it follows
    near = contacts * (1.0 + 0.5 * OFFSET_STEP / 0.10)
    assert not offset_outer_mean(m, near, policy) and abs(m.outer_mean - (1.0 - gap / policy.ramp)) < 1e-15
    deeper = contacts * (1.0 - 2 * OFFSET_STEP / 0.10)
    assert offset_outer_mean(m, deeper, policy)
    assert abs(m.outer_mean - (1.0 - cover_gap(deeper, seen, reach=0.02) / policy.ramp)) < 1e-15
    assert m.outer_mean < 1.0 - gap / policy.ramp


def test_the_policy_refuses_a_cover_offset_that_is_not_a_switch():
    for bad in (1, "yes", None, 0.5):
        with pytest.raises(ValueError, match="cover_offset"):
            ObservationPolicy(cover_offset=bad)


@pytest.mark.parametrize("cover", [0.008, 0.04, 0.05], ids=["tight", "wide", "wider"])
def test_the_cameras_inside_points_are_continued_down_to_the_gap_with_the_offset(cover):
    """``vision_inside_deep``: a body of 10 cm radius under a cover ``cover`` off it, the camera's inside points
    2 cm behind the seen cover. Once five contacts show a gap beyond the 3 cm limit, they are kept (not retracted)
    and continued along the radius every 2 cm down to the gap plus 2 cm, each labelled by its depth (4 cm under the
    4 cm cover; 4 and 6 cm under the 5 cm one), once; under the tight cover, without the offset or with too few
    contacts nothing is added. Each new point lies at its depth below the cover exactly (the sphere's radii)."""
    from torch_gpioius.exploration.observations import (GAP_MIN_CONTACTS, deepen_vision_inside,
                                                        retract_vision_inside)

    policy = ObservationPolicy(vision_inside=0.02, vision_inside_gap=0.03, cover_offset=True, vision_inside_deep=True)
    outer_r = 0.10 + cover
    seen = _sphere(outer_r, 300, seed=4)
    inside = seen * (1.0 - 0.02 / outer_r)
    contacts = _sphere(0.10, 12, seed=5)
    x = np.r_[contacts, seen, inside]
    y = np.r_[np.zeros(len(contacts) + len(seen)), np.full(len(inside), policy.inside_label(0.02))]
    t = np.r_[np.zeros(len(contacts)), np.ones(len(seen) + len(inside))].astype(np.int64)
    m = tg.GPIOIS(torch.as_tensor(x), torch.as_tensor(y), torch.as_tensor(t),
                  kernel=tg.kernels.InverseMultiquadricKernel(0.1))
    assert deepen_vision_inside(m, contacts[:GAP_MIN_CONTACTS - 1], policy) is None
    assert deepen_vision_inside(m, contacts, dataclasses.replace(policy, cover_offset=False)) is None
    assert deepen_vision_inside(m, contacts, dataclasses.replace(policy, vision_inside_deep=False)) is None
    assert len(retract_vision_inside(m, contacts, policy)) == 0                 # kept under the option
    deep = deepen_vision_inside(m, contacts, policy)
    if cover < 0.03:
        assert deep is None
        return
    from torch_gpioius.exploration.observations import cover_gap

    gap = cover_gap(contacts, seen, reach=0.02)                # a plane through the curved cover: a hair under it
    assert cover - 0.005 < gap <= cover
    expected = [d for d in (0.04, 0.06, 0.08) if d <= gap + 0.02]
    depth = policy.inside_depth(deep.y)
    np.testing.assert_allclose(np.unique(depth.round(12)), expected, atol=1e-12)
    assert (deep.task == 1).all() and deep.source == "camera-deep"
    np.testing.assert_allclose(np.linalg.norm(deep.x, axis=1), outer_r - depth, atol=1e-12)
    assert len(deep) == len(inside) * len(expected)              # the sphere contradicts none of them
    m.add_observations(deep.x, deep.y, deep.task)
    assert deepen_vision_inside(m, contacts, policy) is None                    # once


def test_the_gaps_spread_is_their_interquartile_range_over_their_median():
    """gap_spread against a by-hand count: for 1..9 cm the quartiles are 3 and 7 cm and the median 5 cm (0.8); one
    gap everywhere is 0; fewer than GAP_MIN_CONTACTS gaps, or a median of 0, say nothing (NaN)."""
    from torch_gpioius.exploration.observations import GAP_MIN_CONTACTS, gap_spread

    assert gap_spread(np.arange(1, 10) / 100) == pytest.approx(0.8, abs=1e-12)
    assert gap_spread(np.full(7, 0.04)) == 0.0
    assert np.isnan(gap_spread(np.full(GAP_MIN_CONTACTS - 1, 0.04)))
    assert np.isnan(gap_spread(np.zeros(9)))


def _half_uneven_model(policy):
    """A body of 10 cm radius under a cover standing off 4 cm over its upper half and from 4 cm at the equator to
    9 cm at the bottom (a garment hanging below), seen all round, with the camera's inside points 2 cm behind the
    cover; 12 contacts on the upper half, 30 on the lower."""
    dirs = _sphere(1.0, 400, seed=4)
    outer_r = 0.14 + 0.05 * np.clip(-dirs[:, 2], 0.0, None)
    seen, inside = dirs * outer_r[:, None], dirs * (outer_r - 0.02)[:, None]
    around = _sphere(0.10, 200, seed=5)
    upper, lower = around[around[:, 2] > 0.03][:12], around[around[:, 2] < -0.03][:30]
    x = np.r_[upper, lower, seen, inside]
    y = np.r_[np.zeros(len(upper) + len(lower) + len(seen)), np.full(len(inside), policy.inside_label(0.02))]
    t = np.r_[np.zeros(len(upper) + len(lower)), np.ones(len(seen) + len(inside))].astype(np.int64)
    m = tg.GPIOIS(torch.as_tensor(x), torch.as_tensor(y), torch.as_tensor(t),
                  kernel=tg.kernels.InverseMultiquadricKernel(0.1))
    return m, upper, np.r_[upper, lower]


def _one_step(m, contacts, policy):
    """What the exploration does with the cover's gap at a step (exploration.loop._learn): retract, offset, deepen."""
    from torch_gpioius.exploration.observations import (deepen_vision_inside, offset_outer_mean,
                                                        renew_deep_vision_inside, retract_vision_inside)

    removed = retract_vision_inside(m, contacts, policy)
    changed = offset_outer_mean(m, contacts, policy)
    if changed:                                              # the field moved: its deep points placed again
        renewed = renew_deep_vision_inside(m, policy)
        assert not len(removed) or not len(renewed)          # (two removals in one step would need re-indexing)
        removed = renewed if len(renewed) else removed
    deep = deepen_vision_inside(m, contacts, policy)
    if deep is not None:
        m.add_observations(deep.x, deep.y, deep.task)
    return removed, changed, deep


def test_an_even_gap_is_taken_and_once_the_touches_spread_the_camera_falls_back_for_good():
    """``cover_even``: the contacts on the upper half read one 4 cm gap (spread near 0): the outer mean stands for
    it and the camera's inside points are kept and continued, as the gap settings do. The contacts below read 4-9
    cm: past ``cover_even`` the outer mean goes back to 1 and every camera inside point, first and continued, is
    retracted, as the default does past the limit, and stays so with the even contacts again. Without
    ``cover_even`` the same contacts keep the offset; contacts that are uneven from the start never set it."""
    from torch_gpioius.exploration.observations import CoverGap, gap_spread

    policy = ObservationPolicy(vision_inside=0.02, vision_inside_gap=0.03, cover_offset=True, vision_inside_deep=True,
                               cover_even=0.3)
    m, upper, everywhere = _half_uneven_model(policy)
    seen = m.train_inputs[0].numpy()[(m.train_task.numpy() == 1) & (m.train_targets.numpy() == 0)]
    assert gap_spread(CoverGap().measured(upper, seen, 0.02)[1]) < 0.1
    assert gap_spread(CoverGap().measured(everywhere, seen, 0.02)[1]) > 0.3
    removed, changed, deep = _one_step(m, upper, policy)
    assert len(removed) == 0 and changed and m.outer_mean < 1.0 - 0.03 / policy.ramp and deep is not None
    inside_rows = int((m.train_targets < 0).sum())
    removed, changed, deep = _one_step(m, everywhere, policy)
    assert len(removed) == inside_rows and changed and m.outer_mean == 1.0 and deep is None
    assert not (m.train_targets < 0).any()
    removed, changed, deep = _one_step(m, upper, policy)                          # for good
    assert len(removed) == 0 and not changed and m.outer_mean == 1.0 and deep is None
    plain, _, _ = _half_uneven_model(policy)
    loose = dataclasses.replace(policy, cover_even=None)
    _one_step(plain, upper, loose)
    _, changed, _ = _one_step(plain, everywhere, loose)
    assert plain.outer_mean < 1.0 - 0.03 / policy.ramp and (plain.train_targets < 0).any()
    first, _, _ = _half_uneven_model(policy)
    removed, changed, deep = _one_step(first, everywhere, policy)
    assert len(removed) > 0 and not changed and first.outer_mean == 1.0 and deep is None
    for bad in (0.0, -0.1, 2.5, float("nan"), True):
        with pytest.raises(ValueError, match="cover_even"):
            ObservationPolicy(cover_even=bad)


def test_a_gap_the_touches_stop_agreeing_on_becomes_a_gap_per_place_for_good(monkeypatch):
    """``cover_uneven_field``: the even upper contacts set the one gap as ``cover_even`` does; once the lower ones
    spread the gaps, the outer mean becomes the field of the contacts' gaps (reading about 4 cm above and more below,
    as the cover stands), the camera's first inside points are kept and those continued at the one gap are placed
    again from the field (deeper below, where it hangs further off); the even contacts again leave the field. Where
    the touches spread before the field can be judged (seven places), the one gap is kept until it can. A cover
    uneven from the touches' first judgement is retracted as ``cover_even`` does, and so is one whose field does not
    pass the limit at a region of the places (``FIELD_SHARE`` made unreachable): every step then equals
    ``cover_even``'s alone. Without ``cover_even``, or beside ``cover_gap_field``, the setting does nothing."""
    from torch_gpioius.exploration import observations as obs

    policy = ObservationPolicy(vision_inside=0.02, vision_inside_gap=0.03, cover_offset=True, vision_inside_deep=True,
                               cover_even=0.3, cover_uneven_field=True)
    plain = dataclasses.replace(policy, cover_uneven_field=False)
    m, upper, everywhere = _half_uneven_model(policy)
    first = policy.inside_label(0.02)
    n_first = int((m.train_targets.numpy() == first).sum())
    removed, changed, deep = _one_step(m, upper, policy)
    assert len(removed) == 0 and changed and m.outer_field is None and m.outer_mean < 1.0 - 0.03 / policy.ramp
    one_gap_deep = deep.x
    removed, changed, deep = _one_step(m, everywhere, policy)
    field = m.outer_field
    assert changed and field is not None and len(removed) == len(one_gap_deep)   # the one gap's deep points
    y = m.train_targets.numpy()
    assert int((y == first).sum()) == n_first and (y < first - 1e-9).any()        # first kept, continued again
    seen = m.train_inputs[0].numpy()[(m.train_task.numpy() == 1) & (y == 0)]
    top, bottom = seen[:, 2] > 0.08, seen[:, 2] < -0.12
    assert 0.03 < np.median(field.gap(seen[top]).numpy()) < 0.05
    assert np.median(field.gap(seen[bottom]).numpy()) > np.median(field.gap(seen[top]).numpy()) + 0.01
    _one_step(m, upper, policy)                             # for good: the field stays (renewed from these)
    y = m.train_targets.numpy()
    assert m.outer_field is not None and int((y == first).sum()) == n_first and (y < first - 1e-9).any()
    # the one gap taken on five even places, then two lower ones spread them (3.6-8.8 cm) on seven places: kept
    # (cover_even alone gives it up), and the field taken once more contacts come
    lower = everywhere[len(upper):]
    deepest = lower[np.argsort(lower[:, 2])]
    waits, _, _ = _half_uneven_model(policy)
    alone, _, _ = _half_uneven_model(policy)
    for mm, p in ((waits, policy), (alone, plain)):
        assert _one_step(mm, upper[:6], p)[1] and mm.outer_mean < 1.0
    held = waits.outer_mean
    assert len(_one_step(alone, np.r_[upper[:6], deepest[:2]], plain)[0]) > 0 and alone.outer_mean == 1.0
    removed, changed, _ = _one_step(waits, np.r_[upper[:6], deepest[:2]], policy)
    assert len(removed) == 0 and not changed and waits.outer_mean == held and waits.outer_field is None
    _, changed, _ = _one_step(waits, everywhere, policy)
    assert changed and waits.outer_field is not None and int((waits.train_targets.numpy() == first).sum()) == n_first
    # uneven from the first judgement (every contact at once; a cover 2 to 6.5 cm off): cover_even's retraction
    dirs, outer_r = _uneven_sphere(400, seed=4)
    contacts = _sphere(0.10, 60, seed=5)
    for make, c in ((lambda: _half_uneven_model(policy)[0], everywhere),
                    (lambda: _gap_field_model(policy, dirs, outer_r + 0.015, contacts)[0], contacts)):
        a = make()
        removed = _steps_as_cover_even(a, make(), [c], policy, plain)
        assert len(removed) > 0 and a.outer_mean == 1.0
    monkeypatch.setattr(obs, "FIELD_SHARE", 1.01)                                 # the field never passes a region
    _steps_as_cover_even(_half_uneven_model(policy)[0], _half_uneven_model(policy)[0], [upper, everywhere, upper],
                         policy, plain)
    monkeypatch.undo()
    # where no gap is ever given up (cover_even off) or the field is taken whatever the spread (cover_gap_field),
    # the setting does nothing: every step equals the same policy's without it
    for other in ({"cover_even": None}, {"cover_gap_field": True}):
        on = dataclasses.replace(policy, **other)
        off = dataclasses.replace(on, cover_uneven_field=False)
        _steps_as_cover_even(_half_uneven_model(on)[0], _half_uneven_model(off)[0], [upper, everywhere, upper],
                             on, off, seen=seen)


def _steps_as_cover_even(a, b, contacts_seq, policy, plain, seen=None):
    """Each step of the model ``a`` under ``policy`` (``cover_uneven_field``) equals the model ``b``'s under
    ``plain`` (without it; ``cover_even`` alone): the rows removed, whether the mean changed, the labels, and the
    mean with no field on either; or, given the ``seen`` points `(n, 3)`, where ``b`` holds a field too, the same
    field's gap there. Returns the last step's removed rows."""
    for c in contacts_seq:
        ra, ca, _ = _one_step(a, c, policy)
        rb, cb, _ = _one_step(b, c, plain)
        np.testing.assert_array_equal(ra, rb)
        np.testing.assert_array_equal(a.train_targets.numpy(), b.train_targets.numpy())
        assert ca == cb and (a.outer_field is None) == (b.outer_field is None)
        if seen is None or a.outer_field is None:
            assert a.outer_mean == b.outer_mean and a.outer_field is None
        else:
            np.testing.assert_array_equal(a.outer_field.gap(seen).numpy(), b.outer_field.gap(seen).numpy())
    return ra


def _uneven_sphere(n, seed, thin=0.005, thick=0.05):
    """Directions on the unit sphere and a cover over a 10 cm sphere standing off by ``thin`` at the bottom (-z)
    growing linearly in z to ``thick`` at the top."""
    d = _sphere(1.0, n, seed=seed)
    return d, 0.10 + thin + (thick - thin) * (d[:, 2] + 1) / 2


def _gap_field_model(policy, seen_dirs, outer_r, contacts):
    seen = seen_dirs * outer_r[:, None]
    inside = seen_dirs * (outer_r - 0.02)[:, None]
    x = np.r_[contacts, seen, inside]
    y = np.r_[np.zeros(len(contacts) + len(seen)), np.full(len(inside), policy.inside_label(0.02))]
    t = np.r_[np.zeros(len(contacts)), np.ones(len(seen) + len(inside))].astype(np.int64)
    return tg.GPIOIS(torch.as_tensor(x), torch.as_tensor(y), torch.as_tensor(t),
                     kernel=tg.kernels.InverseMultiquadricKernel(0.1)), seen


def test_the_gap_field_follows_a_cover_whose_gap_varies_and_leaves_a_tight_one_alone():
    """``cover_gap_field``: a body of 10 cm radius under a cover 5 mm off at the bottom and 5 cm at the top, touched
    all round (60 contacts). The outer mean becomes a field that reads the gap where it is (within 8 mm, the local
    planes' sagitta and the field's smoothing) instead of one median; a second call with the same contacts changes
    nothing. Under a cover 8 mm off everywhere the field never exceeds the 3 cm limit and the mean stays 1, nor with
    six odd contacts in one spot where it does (fewer than a quarter of the places); the setting alone, without the
    offset and the deep points it stands in for, is refused."""
    from torch_gpioius.exploration.observations import offset_outer_mean

    policy = ObservationPolicy(vision_inside=0.02, vision_inside_gap=0.03, cover_offset=True, vision_inside_deep=True,
                               cover_gap_field=True)
    dirs, outer_r = _uneven_sphere(400, seed=4)
    contacts = _sphere(0.10, 60, seed=5)
    m, seen = _gap_field_model(policy, dirs, outer_r, contacts)
    assert offset_outer_mean(m, contacts, policy) and m.outer_field is not None
    true_gap = outer_r - 0.10
    reads = m.outer_field.gap(seen).numpy()
    band = np.abs(dirs[:, 2]) < 0.8                   # away from the poles, where the contacts surround the place
    assert np.abs(reads - true_gap)[band].max() < 0.008
    assert reads[dirs[:, 2] < -0.8].mean() < 0.015 and reads[dirs[:, 2] > 0.8].mean() > 0.04
    field = m.outer_field
    assert not offset_outer_mean(m, contacts, policy) and m.outer_field is field
    tight, _ = _gap_field_model(policy, dirs, np.full(len(dirs), 0.108), contacts)
    assert not offset_outer_mean(tight, contacts, policy) and tight.outer_field is None and tight.outer_mean == 1.0
    # six contacts close together 5 cm under the tight cover (as beside a seen edge, where the local plane reads
    # centimetres): the field passes 3 cm there, at fewer than a quarter of the places measured: no firing
    from torch_gpioius.exploration.observations import CoverGap
    from torch_gpioius.models.gapfield import GapField

    spot = np.array([1.0, 0.0, 0.0]) + 0.15 * _sphere(1.0, 6, seed=9)
    odd = np.r_[contacts, 0.058 * spot / np.linalg.norm(spot, axis=1, keepdims=True)]
    feet, gaps = CoverGap().measured(odd, dirs * 0.108, reach=0.02)
    assert GapField.fit(feet, np.clip(gaps, 0, 0.1)).gap(feet).max() > 0.03
    assert not offset_outer_mean(tight, odd, policy) and tight.outer_field is None
    with pytest.raises(ValueError, match="cover_gap_field"):
        ObservationPolicy(vision_inside=0.02, vision_inside_gap=0.03, cover_offset=True, cover_gap_field=True)


def test_the_cameras_inside_points_go_down_to_the_fields_gap_where_each_lies_and_are_placed_again():
    """With the gap field, each of the camera's inside points is continued every 2 cm down to the field's gap at its
    seen point plus 2 cm: none where the cover is thin, down to 6 cm where it stands 4-5 cm off; each new point lies
    at its labelled depth below the cover. ``renew_deep_vision_inside`` removes exactly those points, and they are
    placed again alike."""
    from torch_gpioius.exploration.observations import (deepen_vision_inside, offset_outer_mean,
                                                        renew_deep_vision_inside)

    policy = ObservationPolicy(vision_inside=0.02, vision_inside_gap=0.03, cover_offset=True, vision_inside_deep=True,
                               cover_gap_field=True)
    dirs, outer_r = _uneven_sphere(400, seed=4)
    contacts = _sphere(0.10, 60, seed=5)
    m, seen = _gap_field_model(policy, dirs, outer_r, contacts)
    assert deepen_vision_inside(m, contacts, policy) is None                     # no field yet
    assert offset_outer_mean(m, contacts, policy)
    deep = deepen_vision_inside(m, contacts, policy)
    depth = policy.inside_depth(deep.y)
    # each inside point's line runs from its nearest seen point through it; the new points lie on those lines
    from scipy.spatial import cKDTree

    inside = dirs * (outer_r - 0.02)[:, None]
    _, near = cKDTree(seen).query(inside)
    lines = [(seen[k], (p - seen[k]) / np.linalg.norm(p - seen[k])) for p, k in zip(inside, near)]
    j = []
    for p, d in zip(deep.x, depth):
        hit = [i for i, (s0, u) in enumerate(lines) if np.linalg.norm(s0 + u * d - p) < 1e-12]
        assert hit, "a deep point off every inside point's line"
        j.append(near[hit[0]])
    j = np.array(j)
    local = m.outer_field.gap(seen[j]).numpy()
    assert (depth <= local + policy.vision_inside + 1e-9).all()
    assert set(np.unique(depth.round(12))) == {0.04, 0.06}
    assert not (dirs[j, 2] < -0.5).any()                                         # none where the cover is thin
    m.add_observations(deep.x, deep.y, deep.task)
    assert deepen_vision_inside(m, contacts, policy) is None                     # continued already
    n = len(m.train_targets)
    gone = renew_deep_vision_inside(m, policy)
    np.testing.assert_array_equal(gone, np.arange(n - len(deep), n))
    again = deepen_vision_inside(m, contacts, policy)
    np.testing.assert_array_equal(again.x, deep.x)
    np.testing.assert_array_equal(again.y, deep.y)
    plain, _ = _gap_field_model(policy, dirs, outer_r, contacts)                 # no field, none to renew
    assert len(renew_deep_vision_inside(plain, dataclasses.replace(policy, cover_gap_field=False))) == 0


def test_a_noisy_camera_smoothed_along_its_rays_keeps_its_surface_in_place():
    """With 8 mm of depth noise a tenth of the 2 cm voxels' means of a 10 cm sphere's cloud land 4 mm or more inside
    it, the deepest over a centimetre (the noise carries points into the voxels behind the surface); with each point
    averaged in the voxel of its depth smoothed along the rays (``ObservationPolicy.ray_smoothing``) few do, and none
    that deep. The free space and the candidate inside points are the measured cloud's either way; fewer of these are
    contradicted by a seen point."""
    import trimesh

    from torch_gpioius.sensors import PinholeCamera, SimulatedDepthCamera, look_at
    from torch_gpioius.geometry.voxels import voxel_average

    centre, radius = np.array([0.5, 0.0, 0.25]), 0.1
    mesh = trimesh.creation.icosphere(subdivisions=5, radius=radius)
    mesh.apply_translation(centre)
    cloud = SimulatedDepthCamera(mesh, PinholeCamera.kinect_v2(0.5), look_at([0.5, -0.8, 0.9], centre),
                                 noise_a=0.008, seed=5).capture()
    raw = ObservationPolicy(voxel=0.02, vision_inside=0.02)
    smooth = dataclasses.replace(raw, ray_smoothing=24)
    (xr, yr), (xs, ys) = vision_observations(cloud, raw), vision_observations(cloud, smooth)
    deep = {}
    for name, (x, y) in (("raw", (xr, yr)), ("smooth", (xs, ys))):
        depth = radius - np.linalg.norm(x[y == 0] - centre, axis=1)
        deep[name] = ((depth > 0.004).mean(), depth.max())
    assert deep["raw"][0] > 0.1 and deep["raw"][1] > 0.012              # measured: 15 %, 14 mm
    assert deep["smooth"][0] < 0.07 and deep["smooth"][1] < 0.01          # measured: 4.3 %, 8.2 mm
    # the seen points: the measured points' means over the voxels their smoothed depths choose
    np.testing.assert_allclose(xs[ys == 0], voxel_average(cloud.points, 0.02, at=cloud.smoothed_along_rays(24).points),
                               atol=1e-12)
    np.testing.assert_array_equal(xs[ys == 1], xr[yr == 1])                # free space: the measured cloud's
    candidates = {tuple(p) for p in cloud.behind(0.02, 0.02)}               # inside points: among its candidates,
    assert {tuple(p) for p in xs[ys < 0]} <= candidates and (ys < 0).sum() > (yr < 0).sum()   # fewer contradicted


def test_a_repeated_contact_enters_k_times_and_its_inside_and_free_points_once():
    contact = np.array([0.3, 0.1, 0.2])
    force = np.array([0.0, 3.0, 4.0])
    free = contact + np.outer(np.linspace(0.03, 0.09, 4), [0.0, 0.6, 0.8])
    one = PointTouch().observations(_touch(contact, force, free), contact[None],
                                    ObservationPolicy(touch_inside=0.02), 3)
    four = PointTouch().observations(_touch(contact, force, free), contact[None],
                                     ObservationPolicy(touch_inside=0.02, contact_repeats=4), 3)
    assert len(four) == len(one) + 3
    np.testing.assert_array_equal(four.x[:4], np.repeat(contact[None], 4, axis=0))
    assert four.y[:4].tolist() == [0.0] * 4 and (four.task == 0).all()
    np.testing.assert_array_equal(four.x[4:], one.x[1:])          # the inside point and the free space, once
    for bad in (0, 65, 2.5, True, "4"):
        with pytest.raises(ValueError, match="contact_repeats"):
            ObservationPolicy(contact_repeats=bad)


def test_a_contact_repeated_k_times_is_one_contact_with_a_kth_of_the_noise():
    """The model with each contact row k times (one sigma^2) equals, in its inner and outer posterior means and
    variances, a dense Gaussian process written out here with the contacts' noise sigma^2 / k; its marginal likelihood
    differs from that one's by the same constant at every K_t, so K_t's optimum is the same."""
    from torch_gpioius.kernels import Matern52

    rng = np.random.default_rng(0)
    sphere = rng.standard_normal((60, 3))
    sphere /= np.linalg.norm(sphere, axis=1, keepdims=True)
    contacts, seen = 0.10 * sphere[:12], 0.108 * sphere[12:]
    k, s = 4, 0.08
    x_ref = np.concatenate([contacts, contacts * 1.5, seen, seen * 1.46])
    y_ref = np.concatenate([np.zeros(12), np.ones(12), np.zeros(48), np.ones(48)])
    t_ref = np.concatenate([np.zeros(24, np.int64), np.ones(96, np.int64)])
    noise_ref = np.where((t_ref == 0) & (y_ref == 0), s / k, s)
    x = np.concatenate([np.repeat(contacts, k, axis=0), x_ref[12:]])
    y = np.concatenate([np.zeros(12 * k), y_ref[12:]])
    t = np.concatenate([np.zeros(12 * k, np.int64), t_ref[12:]])
    kernel = Matern52(0.05)

    def reference(kt, q, task):
        xt, tt = torch.as_tensor(x_ref), torch.as_tensor(t_ref)
        g = kernel.value(xt, xt) * kt[tt][:, tt] + torch.diag(torch.as_tensor(noise_ref))
        cross = kernel.value(torch.as_tensor(q), xt) * kt[task, tt]
        mean = 1.0 + cross @ torch.linalg.solve(g, torch.as_tensor(y_ref) - 1.0)
        var = kt[task, task] * kernel.value(torch.as_tensor(q[:1]), torch.as_tensor(q[:1]))[0, 0] - (
            cross * torch.linalg.solve(g, cross.T).T).sum(1)
        chol = torch.linalg.cholesky(g)
        r = torch.as_tensor(y_ref) - 1.0
        mll = -0.5 * r @ torch.cholesky_solve(r[:, None], chol)[:, 0] - chol.diagonal().log().sum()
        return mean.numpy(), var.numpy(), float(mll)

    q = rng.uniform(-0.15, 0.15, (40, 3))
    constants = []
    for kt in ([[1.0, 0.9], [0.9, 1.2]], [[0.7, 0.3], [0.3, 1.5]]):
        for inference in ("dense", "structured"):
            model = tg.GPIOIS(x, y, t, noise=s, kernel=Matern52(0.05), inference=inference)
            model.task_covariance = kt
            for task in (0, 1):
                mean, var = model.predict(torch.as_tensor(q), task=task)
                ref_mean, ref_var, ref_mll = reference(torch.tensor(kt, dtype=torch.float64), q, task)
                np.testing.assert_allclose(mean.detach().numpy(), ref_mean, atol=1e-9)
                np.testing.assert_allclose(var.detach().numpy(), ref_var, atol=1e-9)
        constants.append(float(model.log_marginal_likelihood()) - ref_mll)
    assert constants[0] == pytest.approx(constants[1], abs=1e-6)


def test_a_thin_part_gets_its_camera_inside_points_at_half_the_depth_with_halvings():
    """A slab 2.4 cm thick seen from above and below: 2 cm behind either face lies 4 mm from the other, so every
    inside point is contradicted and none is kept (the default). With ``inside_halvings`` each is tried again 1 cm
    behind the same voxel, which nothing contradicts: labelled by that depth, all inside the slab, one per seen
    voxel. A slab thicker than 4 cm keeps its 2 cm points with or without halvings: the setting changes nothing
    where nothing was contradicted."""
    from torch_gpioius.sensors.pointcloud import PointCloud

    def slab(half):
        g = np.stack(np.meshgrid(np.linspace(-0.1, 0.1, 41), np.linspace(-0.1, 0.1, 41)), -1).reshape(-1, 2)
        top = PointCloud(np.c_[g, np.full(len(g), half)], np.array([0.0, 0.0, 1.0]))
        bottom = PointCloud(np.c_[g, np.full(len(g), -half)], np.array([0.0, 0.0, -1.0]))
        return PointCloud.merge([top, bottom])

    base = ObservationPolicy(vision_inside=0.02, voxel=0.02)
    halved = dataclasses.replace(base, inside_halvings=2)
    x0, y0 = vision_observations(slab(0.012), base)
    assert not (y0 < 0).any()                                  # the far face 4 mm from every 2 cm point
    x1, y1 = vision_observations(slab(0.012), halved)
    inside = y1 < 0
    seen = (y1 == 0).sum()
    assert inside.sum() == seen                                 # one per seen voxel, at the first depth kept
    np.testing.assert_allclose(y1[inside], base.inside_label(0.01))
    np.testing.assert_allclose(np.abs(x1[inside, 2]), 0.002, atol=1e-9)   # 1 cm behind a face 1.2 cm out
    np.testing.assert_array_equal(x1[~inside], x0)              # the rest as without
    # thick: the same observations with or without halvings
    xa, ya = vision_observations(slab(0.03), base)
    xb, yb = vision_observations(slab(0.03), halved)
    assert (ya < 0).sum() == (ya == 0).sum()
    np.testing.assert_array_equal(xa, xb)
    np.testing.assert_array_equal(ya, yb)
    with pytest.raises(ValueError, match="inside_halvings"):
        ObservationPolicy(inside_halvings=5)



def test_a_stray_voxel_in_front_of_a_face_gets_no_shallower_inside_point():
    """Depth noise at grazing rays can leave a voxel mean a centimetre in front of the face it belongs to; its 2 cm
    point then lies near that face, seen from the same side, and is contradicted. That is no thin part (nothing
    faces the other way), and halving it would put an inside point in front of the face: none is placed."""
    from torch_gpioius.sensors.pointcloud import PointCloud

    g = np.stack(np.meshgrid(np.linspace(-0.1, 0.1, 41), np.linspace(-0.1, 0.1, 41)), -1).reshape(-1, 2)
    face = np.c_[g, np.full(len(g), -0.001)]
    p = np.stack(np.meshgrid(np.linspace(0.0, 0.015, 4), np.linspace(0.0, 0.015, 4)), -1).reshape(-1, 2)
    stray = np.c_[p + 0.041, np.full(len(p), 0.012)]               # a voxel of its own, 13 mm in front of the face
    cloud = PointCloud(np.r_[face, stray], np.array([0.0, 0.0, 1.0]))
    base = ObservationPolicy(vision_inside=0.02, voxel=0.02)
    x0, y0 = vision_observations(cloud, base)
    x1, y1 = vision_observations(cloud, dataclasses.replace(base, inside_halvings=2))
    assert (y0 < 0).sum() < (y0 == 0).sum()                        # the stray's 2 cm point was contradicted
    np.testing.assert_array_equal(x0, x1)
    np.testing.assert_array_equal(y0, y1)


def test_a_thin_part_in_2d_gets_inside_points_at_half_the_depth_and_a_thick_part_keeps_its_own():
    """The 2-D world's view is sampled afresh at each depth: a 3 cm sliver has no points 2 cm in (thinner than twice
    that) and gets them 1 cm in with one halving; a disc keeps its 2 cm ring and gets no second one inside it."""
    sliver = shapely.geometry.box(0.0, 0.0, 0.2, 0.03)
    ring = sliver.exterior
    view = PlanarView(np.array([ring.interpolate(s).coords[0] for s in np.arange(0.0, ring.length, 0.005)]),
                      origin=None, polygon=sliver, spacing=0.005)
    base = ObservationPolicy(vision_inside=0.02)
    halved = dataclasses.replace(base, inside_halvings=1)
    assert not (vision_observations(view, base)[1] < 0).any()
    x, y = vision_observations(view, halved)
    assert (y < 0).sum() > 20 and np.allclose(y[y < 0], base.inside_label(0.01))
    depth = np.array([sliver.exterior.distance(shapely.geometry.Point(p)) for p in x[y < 0]])
    np.testing.assert_allclose(depth, 0.01, atol=1e-9)
    disc = shapely.geometry.Point(0.0, 0.0).buffer(0.1, 256)
    view = PlanarView(np.array(disc.exterior.coords)[:-1], origin=None, polygon=disc, spacing=0.01)
    xa, ya = vision_observations(view, base)
    xb, yb = vision_observations(view, halved)
    np.testing.assert_array_equal(xa, xb)
    np.testing.assert_array_equal(ya, yb)
    # a disc with a 3 cm arm: every 2 cm point of the disc is kept, and the arm still gets its 1 cm ones
    body = disc.union(shapely.geometry.box(0.05, -0.015, 0.3, 0.015))
    ring = body.exterior
    view = PlanarView(np.array([ring.interpolate(s).coords[0] for s in np.arange(0.0, ring.length, 0.005)]),
                      origin=None, polygon=body, spacing=0.005)
    x, y = vision_observations(view, halved)
    arm = (y < 0) & (x[:, 0] > 0.15)
    assert arm.sum() > 10 and np.allclose(y[arm], base.inside_label(0.01))
    assert (y == base.inside_label(0.02)).sum() > 10


def _task_covariance(r: float, outer: float = 1.2, inner: float = 1.0) -> torch.Tensor:
    """A K_t whose transfer ``K_t[0,1] / K_t[1,1]`` is ``r``."""
    c = r * outer
    assert c * c <= inner * outer
    return torch.tensor([[inner, c], [c, outer]], dtype=torch.float64)


@pytest.mark.parametrize("r", [0.8, 0.6])
def test_the_carried_mean_puts_the_inner_zero_level_where_the_outer_field_reads_the_gap(r):
    """Without inner observations the inner posterior mean is the outer residual carried across: ``1 + r (mu_out -
    m_out)`` exactly (a multi-task GP's closed form, ``r = K_t[0,1] / K_t[1,1]``). With the outer mean at
    ``carried_mean(1 - g / ramp)`` it is ``r (mu_out + g / ramp)``: zero exactly where the outer field reads the
    gap's level, the body ``g`` below the cover; with ``1 - g / ramp`` alone it is ``1 - r`` there (the estimate
    sinks). A cover 4 cm off a sphere seen all round, inside points down to the gap, free space 5 cm out."""
    from torch_gpioius.exploration.observations import carried_mean

    policy = ObservationPolicy()
    gap, cover = 0.04, 0.14
    seen = _sphere(cover, 200, seed=3)
    unit = seen / cover
    x = np.r_[seen, seen - 0.02 * unit, seen - gap * unit, seen + 0.05 * unit]
    y = np.r_[np.zeros(len(seen)), np.full(len(seen), policy.inside_label(0.02)),
              np.full(len(seen), policy.inside_label(gap)), np.ones(len(seen))]
    m = tg.GPIOIS(torch.as_tensor(x), torch.as_tensor(y), torch.ones(len(x), dtype=torch.int64), noise=0.08,
                  kernel=tg.kernels.Matern52(0.04), task_covariance=_task_covariance(r))
    base = 1.0 - gap / policy.ramp
    carried = carried_mean(base, m.task_covariance)
    assert carried == pytest.approx(base + 1.0 / r - 1.0, abs=1e-12)
    q = torch.as_tensor(_sphere(1.0, 50, seed=8) * np.random.default_rng(8).uniform(0.08, 0.16, (50, 1)))
    for mean in (base, carried):
        m.set_outer_mean(mean)
        inner, outer = m.predict_mean(q, 0).detach(), m.predict_mean(q, 1).detach()
        torch.testing.assert_close(inner, 1.0 + r * (outer - mean), rtol=0, atol=1e-10)
    torch.testing.assert_close(inner, r * (outer + gap / policy.ramp), rtol=0, atol=1e-10)


def test_the_carried_mean_is_bounded_and_left_alone_without_a_transfer():
    """The transfer is floored at CARRY_MIN_RATIO (a correction of at most one label unit); a K_t whose tasks share
    nothing (r = 0), disagree in sign or has no outer variance leaves the mean as it is."""
    from torch_gpioius.exploration.observations import CARRY_MIN_RATIO, carried_mean

    assert carried_mean(0.2, _task_covariance(0.3)) == pytest.approx(0.2 + 1.0 / CARRY_MIN_RATIO - 1.0, abs=1e-12)
    assert carried_mean(0.2, _task_covariance(1.0, inner=1.5)) == pytest.approx(0.2, abs=1e-12)
    assert carried_mean(0.2, torch.eye(2, dtype=torch.float64)) == 0.2
    assert carried_mean(0.2, _task_covariance(-0.5)) == 0.2
    assert carried_mean(0.2, torch.tensor([[1.0, 0.0], [0.0, 0.0]], dtype=torch.float64)) == 0.2
    assert carried_mean(0.2, np.full((2, 2), np.nan)) == 0.2


def test_the_outer_mean_is_carried_through_the_learned_transfer_once_set():
    """The wide cover of the tests above, K_t with r = 0.8: with ``cover_carry`` the first setting is the gap's own
    ``1 - g / ramp`` (a K_t learned at the mean of 1 carries the gap in its r), the next renews it to
    ``carried_mean`` (a move of 1.25 cm of gap, past OFFSET_STEP), and it then stays while nothing moves; without
    ``cover_carry`` the second call leaves the gap's mean. K_t itself is never changed here."""
    from torch_gpioius.exploration.observations import carried_mean, cover_gap, offset_outer_mean

    policy = ObservationPolicy(vision_inside=0.02, vision_inside_gap=0.02, cover_offset=True, cover_carry=True)
    seen = _sphere(0.14, 300, seed=4)
    contacts = _sphere(0.10, 12, seed=5)
    x, y = np.r_[contacts, seen], np.zeros(len(contacts) + len(seen))
    t = np.r_[np.zeros(len(contacts)), np.ones(len(seen))].astype(np.int64)
    base = 1.0 - cover_gap(contacts, seen, reach=0.02) / policy.ramp
    for carry in (True, False):
        m = tg.GPIOIS(torch.as_tensor(x), torch.as_tensor(y), torch.as_tensor(t),
                      kernel=tg.kernels.InverseMultiquadricKernel(0.1), task_covariance=_task_covariance(0.8))
        kt = m.task_covariance
        p = dataclasses.replace(policy, cover_carry=carry)
        assert offset_outer_mean(m, contacts, p) and abs(m.outer_mean - base) < 1e-15
        assert offset_outer_mean(m, contacts, p) == carry
        assert abs(m.outer_mean - (carried_mean(base, kt) if carry else base)) < 1e-15
        assert not offset_outer_mean(m, contacts, p)
        assert torch.equal(m.task_covariance, kt)
    assert ObservationPolicy().cover_carry is False
    with pytest.raises(ValueError, match="cover_carry"):
        ObservationPolicy(cover_carry=1)


def test_a_gap_field_is_carried_through_the_learned_transfer_as_one_gap_is():
    """``cover_gap_field`` with ``cover_carry``: the field's mean is raised by the same ``1 / r - 1``. Without inner
    observations the inner posterior mean is ``1 + r (mu_out - m_out(x))``, so with the carried field it is ``r
    (mu_out + g(x) / ramp)`` to 1e-10: zero where the outer field reads each place's own gap. In the loop the field is
    set first without the carry, renewed with it from the last fit's K_t (r = 0.8) and then left; without
    ``cover_carry`` the second call leaves it. The carry survives the field's record."""
    from torch_gpioius.exploration.observations import carried_mean, offset_outer_mean
    from torch_gpioius.models.gapfield import GapField

    policy = ObservationPolicy(vision_inside=0.02, vision_inside_gap=0.03, cover_offset=True, vision_inside_deep=True,
                               cover_gap_field=True, cover_carry=True)
    dirs, outer_r = _uneven_sphere(400, seed=4)
    contacts = _sphere(0.10, 60, seed=5)
    for carry in (True, False):
        m, seen = _gap_field_model(policy, dirs, outer_r, contacts)
        m.task_covariance = _task_covariance(0.8)
        kt = m.task_covariance
        p = dataclasses.replace(policy, cover_carry=carry)
        assert offset_outer_mean(m, contacts, p) and m.outer_field.carry == 0.0
        assert offset_outer_mean(m, contacts, p) == carry
        assert m.outer_field.carry == pytest.approx(carried_mean(0.0, kt) if carry else 0.0, abs=1e-15)
        assert not offset_outer_mean(m, contacts, p)
    field = m.outer_field.carried(0.25)
    assert GapField.from_dict(field.as_dict()) == field and "carry" not in m.outer_field.as_dict()
    torch.testing.assert_close(field.mean(seen), m.outer_field.mean(seen) + 0.25, rtol=0, atol=1e-15)
    # the identity, on the camera's observations alone (no inner rows), the field a smooth gap of 0.5-5 cm
    r = 0.7
    x = np.r_[seen, dirs * (outer_r - 0.02)[:, None], dirs * 0.10, seen + 0.05 * dirs]
    y = np.r_[np.zeros(len(seen)), np.full(len(seen), policy.inside_label(0.02)),
              -(outer_r - 0.10) / policy.ramp, np.ones(len(seen))]
    o = tg.GPIOIS(torch.as_tensor(x), torch.as_tensor(y), torch.ones(len(x), dtype=torch.int64), noise=0.08,
                  kernel=tg.kernels.Matern52(0.04), task_covariance=_task_covariance(r))
    gaps = GapField(seen, outer_r - 0.10, 0.08, 0.02, 0.004, ramp=policy.ramp)
    carried = gaps.carried(carried_mean(0.0, o.task_covariance))
    assert carried.carry == pytest.approx(1.0 / r - 1.0, abs=1e-12)
    q = torch.as_tensor(_sphere(1.0, 50, seed=8) * np.random.default_rng(8).uniform(0.08, 0.16, (50, 1)))
    o.set_outer_mean(carried)
    inner, outer = o.predict_mean(q, 0).detach(), o.predict_mean(q, 1).detach()
    torch.testing.assert_close(inner, 1.0 + r * (outer - carried.mean(q)), rtol=0, atol=1e-10)
    torch.testing.assert_close(inner, r * (outer + gaps.gap(q) / policy.ramp), rtol=0, atol=1e-10)
    with pytest.raises(ValueError, match="carry"):
        gaps.carried(1.5)
