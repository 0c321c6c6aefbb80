"""Evidence-seeking taps: they happen where a tap can tell the cover from the body, they change what the model
believes, their motion passes the safety gate, and they are paid for in the travel and step budgets."""

import numpy as np
import pytest

import torch_gpioius as tg

from tests.exploration.gate import assert_within_the_gate


def test_a_tap_over_the_loose_side_removes_the_extension(c_from_the_left, c_left_without_recovery):
    # the plain run stalls in the corner where body and cover part (step 111 on); the no-progress rule's recovery,
    # an approach from the free side, finds the cover's gap by itself, so it is off here to isolate the taps
    plain = c_left_without_recovery
    tapped = tg.explore(c_from_the_left, evidence="taps", max_steps=140, interval_every=1000)
    assert plain.taps[-1] == 0 and plain.correlation[-1] > 0.999
    assert tapped.taps[-1] >= 1
    assert tapped.correlation[-1] < 0.9
    lo, hi = tapped.correlation_interval[-1]
    assert hi < 1.0                                           # the interval excludes 1 once the tap is in
    assert tapped.hausdorff_touched[-1] < 0.5 * plain.hausdorff_touched[-1]


def test_taps_are_paid_for_in_the_budgets(c_from_the_left):
    tapped = tg.explore(c_from_the_left, evidence="taps", max_steps=120)
    steps = tapped.n_steps - 1
    assert steps + int(tapped.taps[-1]) <= 120                   # a tap counts as a step
    # travel: the fingertip's path length (slides, regulation, taps) since the first contact
    path = tapped.path[1:]
    walked = np.linalg.norm(np.diff(path, axis=0), axis=1).sum()
    assert tapped.travel[-1] == pytest.approx(walked, rel=1e-6)
    jump = np.diff(tapped.travel)[np.diff(tapped.taps) > 0]
    assert (jump > 2 * 0.1).all()                               # a tap over 27 cm of cover travels > 20 cm


def test_tap_motion_passes_the_gate_and_tight_covers_get_no_tap():
    from kinematics import SafetyGate  # noqa: F401 - the gate is part of the simulated UR5
    scene = tg.sim.sphere_scene(radius=0.08, cover=0.05, center=(0.5, 0.0, 0.25))
    made = []
    original = scene.hardware
    scene.hardware = lambda: made.append(original()) or made[-1]
    tr = tg.explore(scene, evidence="taps", max_travel=0.6, metrics_every=100)
    del scene.hardware
    assert_within_the_gate(made[0].robot)
    assert tr.taps[-1] >= 1
    tight = tg.sim.sphere_scene(radius=0.08, cover=0.008, center=(0.5, 0.0, 0.25))
    assert tg.explore(tight, evidence="taps", max_travel=0.3, metrics_every=100).taps[-1] == 0


def test_taps_need_visual_tactile():
    with pytest.raises(ValueError, match="visual-tactile"):
        tg.explore(tg.sim.paper_objects_2d()["A"], mode="tactile", evidence="taps")
    with pytest.raises(ValueError, match="evidence"):
        tg.explore(tg.sim.paper_objects_2d()["A"], evidence="pokes")
