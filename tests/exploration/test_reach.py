"""Reaching for unseen surface: the plan goes where the posterior is least sure of the surface, through free space the
model is sure of, within the travel left; the motion passes the safety gate, is paid for in the budgets, and every
way a reach can end (a contact on the way, a refused leg, nothing at the target) leaves a consistent state."""

from types import SimpleNamespace

import numpy as np
import pytest
import torch

import torch_gpioius as tg

from tests.exploration.gate import assert_within_the_gate
from torch_gpioius.exploration.contact import ContactResult
from torch_gpioius.exploration.reach import ReachPolicy
from torch_gpioius.geometry.surfaces import zero_level_mesh

CENTRE = np.array([0.5, 0.0, 0.25])
RADIUS = 0.08


def _fibonacci(n: int) -> np.ndarray:
    i = np.arange(n) + 0.5
    z = 1 - 2 * i / n
    phi = np.pi * (1 + 5 ** 0.5) * i
    r = np.sqrt(1 - z * z)
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)


def _sphere_model(side: str = "upper") -> tg.GPIS:
    """A GPIS of a sphere (radius 8 cm) observed on its upper half only, or all over: surface points (y = 0) and
    free space 5 cm out (y = 1)."""
    u = _fibonacci(400)
    if side == "upper":
        u = u[u[:, 2] > 0.0]
    x = np.concatenate([CENTRE + RADIUS * u, CENTRE + (RADIUS + 0.05) * u])
    y = np.concatenate([np.zeros(len(u)), np.ones(len(u))])
    return tg.GPIS(x, y, kernel=tg.kernels.InverseMultiquadricKernel(0.1), noise=0.01)


def _state(model, contact_dir=(0.0, 0.0, 1.0), travel: float = 0.0):
    n = np.asarray(contact_dir, dtype=np.float64)
    n /= np.linalg.norm(n)
    contact = CENTRE + RADIUS * n
    return SimpleNamespace(model=model, contact=contact, normal=torch.as_tensor(n), steps=20, last_evidence=0,
                           travel=travel)


BOX = np.stack([CENTRE - 0.15, CENTRE + 0.15])


def test_the_plan_goes_to_the_least_certain_surface_through_free_space():
    model = _sphere_model("upper")
    policy = ReachPolicy(bounds=BOX, max_transit=0.6)
    plan = policy.plan(_state(model))
    assert plan is not None
    x = torch.as_tensor(plan.target[None])
    mean, var = model.predict(x)
    # on the estimated surface (the samples lie on a 1.5 cm marching-cubes mesh: linear interpolation error)
    assert abs(float(mean[0])) < 0.02
    assert float(var[0]) == pytest.approx(plan.variance, rel=1e-9)
    # the least certain part of the estimate, by an independent finer mesh of the same field
    fine = zero_level_mesh(model, BOX, 0.008)
    v = fine.vertices[np.linalg.norm(fine.vertices - plan.waypoints[0], axis=1) >= policy.min_distance]
    v = v[((v > BOX[0] + 0.01) & (v < BOX[1] - 0.01)).all(axis=1)]
    v_max = float(model.predict(torch.as_tensor(v))[1].max())
    assert plan.variance >= 0.8 * v_max
    assert plan.target[2] < CENTRE[2]                                   # on the half nothing observed
    assert plan.variance >= policy.min_ratio * plan.near_variance
    # the normal points out of the sphere there
    radial = (plan.target - CENTRE) / np.linalg.norm(plan.target - CENTRE)
    assert float(plan.normal @ radial) > 0.9
    # the route lies in free space the model is sure of (checked here every 5 mm, the plan every 1 cm); it goes
    # round the sphere, which a straight leg from the top to the bottom would cross
    corners = plan.waypoints[1:]
    legs = [a + np.linspace(0, 1, int(np.ceil(np.linalg.norm(b - a) / 0.005)) + 1)[:, None] * (b - a)
            for a, b in zip(corners[:-1], corners[1:])]
    assert float(model.predict_mean(torch.as_tensor(np.concatenate(legs))).min()) >= policy.clear_level - 0.05
    assert len(corners) >= 3
    np.testing.assert_allclose(corners[-1], plan.target + plan.clearance * plan.normal, atol=1e-12)
    lift = float(np.linalg.norm(corners[0] - plan.waypoints[0]))
    expected = lift + float(np.linalg.norm(np.diff(corners, axis=0), axis=1).sum()) + plan.clearance
    assert plan.length == pytest.approx(expected, rel=1e-12) and plan.length <= policy.max_transit


def test_no_reach_when_the_surface_is_known_everywhere_or_the_budget_is_spent():
    seen = _sphere_model("all")
    assert ReachPolicy(bounds=BOX, max_transit=0.6).plan(_state(seen)) is None
    half = _sphere_model("upper")
    full = ReachPolicy(bounds=BOX, max_transit=0.6).plan(_state(half))
    short = ReachPolicy(bounds=BOX, max_transit=0.6, budget=0.5)
    assert short.plan(_state(half, travel=0.5 - 0.5 * full.length)) is None or \
        short.plan(_state(half, travel=0.5 - 0.5 * full.length)).length <= 0.5 * full.length
    assert not short.due(_state(half, travel=0.5 - 0.01))                     # less than min_distance left
    assert short.due(_state(half, travel=0.0))
    assert not ReachPolicy(min_steps=30).due(_state(half))                       # 20 steps since the last


class _Toucher:
    """A scripted toucher: each method returns the next result of its queue, or raises it if it is an exception."""

    def __init__(self, lift, approaches):
        self.lifts, self.approaches, self.calls = [lift], list(approaches), []

    def _next(self, queue, name, *args):
        self.calls.append(name)
        r = queue.pop(0)
        if isinstance(r, Exception):
            raise r
        return r

    def lift(self, direction, **kw):
        # the contact controller's own bounds on a lift (ContactController.lift raises beyond them)
        assert 0 < kw["extra"] <= 0.1 and 0 < kw["max_distance"] <= 2.0
        self.lift_kw = kw
        return self._next(self.lifts, "lift", direction)

    def approach(self, direction, max_travel=0.3):
        assert 0 < max_travel <= 2.0
        return self._next(self.approaches, "approach", direction)

    def slide(self, step, normal):  # pragma: no cover - a reach never slides
        raise AssertionError("slide")


def _result(end, contact: bool, force=(0.0, 0.0, 2.0)):
    end = torch.as_tensor(np.asarray(end, dtype=np.float64))
    return ContactResult(contact, end.clone(), torch.zeros(0, 3, dtype=torch.float64), end[None].clone(),
                         torch.as_tensor([force], dtype=torch.float64), 0.05)


def test_every_way_a_reach_ends_leaves_a_consistent_evidence():
    state = _state(_sphere_model("upper"))
    policy = ReachPolicy(bounds=BOX, max_transit=0.6)
    plan = policy.plan(state)
    lifted, corners = plan.waypoints[1], plan.waypoints[2:]
    legs = [_result(c, False) for c in corners]
    # the whole reach: lift, a leg to each corner, approach to the target
    t = _Toucher(_result(lifted, False), [*legs, _result(plan.target, True, (-2, 0, 0))])
    ev = policy.gather(state, t)
    assert t.calls == ["lift"] + ["approach"] * (len(corners) + 1) and ev.kind == "tap"
    np.testing.assert_allclose(ev.contact, plan.target)
    np.testing.assert_allclose(ev.normal.numpy(), [-1.0, 0.0, 0.0])
    # something where the model saw free space: the reach ends at that contact
    bump = (lifted + corners[0]) / 2
    t = _Toucher(_result(lifted, False), [_result(bump, True)])
    ev = policy.gather(state, t)
    assert t.calls == ["lift", "approach"] and len(ev.touches) == 2
    np.testing.assert_allclose(ev.contact, bump)
    # a refused leg: the motion so far is reported, without a contact (the loop's recovery takes over)
    t = _Toucher(_result(lifted, False), [RuntimeError("outside the workspace")])
    ev = policy.gather(state, t)
    assert ev.contact is None and ev.normal is None and len(ev.touches) == 1
    # nothing at the target: no contact either
    t = _Toucher(_result(lifted, False), [*legs, _result(plan.target, False)])
    assert policy.gather(state, t).contact is None
    # a refused lift: nothing moved, no evidence
    t = _Toucher(RuntimeError("refused"), [])
    assert policy.gather(state, t) is None
    # the largest clearance is the lift's bound itself, 0.1 m: asked for exactly (|0.1 n| rounds to 0.10000000000000003)
    far = ReachPolicy(bounds=BOX, max_transit=0.8, clearances=(0.1,))
    state = _state(state.model, contact_dir=(0.1, 0.7, 1.0))          # a normal for which |0.1 n| > 0.1
    plan = far.plan(state)
    assert float(np.linalg.norm(plan.waypoints[1] - plan.waypoints[0])) > 0.1
    assert plan.lift == 0.1
    t = _Toucher(_result(plan.waypoints[1], False), [_result(c, False) for c in plan.waypoints[2:]] +
                 [_result(plan.target, True)])
    far.gather(state, t)
    assert t.lift_kw["extra"] == 0.1


def test_reach_motion_passes_the_gate_and_is_paid_for_in_the_budgets():
    scene = tg.sim.sphere_scene(radius=RADIUS, cover=0.008, center=tuple(CENTRE))
    made, approaches = [], []
    original = scene.hardware

    def hardware():                      # the run's hardware, its approaches logged
        hw = original()
        made.append(hw)
        approach = hw.controller.approach
        hw.controller.approach = lambda *a, **k: approaches.append(approach(*a, **k)) or approaches[-1]
        return hw

    scene.hardware = hardware
    tr = tg.explore(scene, evidence=ReachPolicy(min_steps=8), max_travel=0.45, metrics_every=100)
    del scene.hardware
    assert_within_the_gate(made[0].robot)
    assert tr.taps[-1] >= 1
    reached = np.flatnonzero(np.diff(tr.taps) > 0) + 1
    # the contact after each reach is on the body (the force field's cover lets the fingertip through)
    for i in reached:
        assert abs(np.linalg.norm(tr.contacts[i] - CENTRE) - RADIUS) < 0.01
    assert float(np.diff(tr.travel)[reached - 1].min()) > 0.05                # a reach travels, and it is counted
    # travel: the fingertip's path length since the first contact (where the first approach's path ends)
    path = tr.path[len(approaches[0].path) - 1:]
    assert tr.travel[-1] == pytest.approx(np.linalg.norm(np.diff(path, axis=0), axis=1).sum(), rel=1e-6)


def test_reach_settings_are_checked():
    with pytest.raises(ValueError, match="min_steps"):
        ReachPolicy(min_steps=0)
    with pytest.raises(ValueError, match="clearances"):
        ReachPolicy(clearances=(0.1, 0.05))
    with pytest.raises(ValueError, match="clearances"):
        ReachPolicy(clearances=(0.2,))
    with pytest.raises(ValueError, match="min_ratio"):
        ReachPolicy(min_ratio=0.5)
    with pytest.raises(ValueError, match="3-D"):
        tg.explore(tg.sim.paper_objects_2d()["A"], evidence="reach")
    # a reach needs no camera; a tap does
    scene = tg.sim.sphere_scene(radius=RADIUS, cover=0.008, center=tuple(CENTRE))
    cfg = tg.exploration.ExploreConfig.from_world(scene, "tactile", evidence="reach", max_travel=0.3)
    assert cfg.evidence.budget == pytest.approx(0.3)
    np.testing.assert_allclose(np.asarray(cfg.evidence.bounds), np.stack([cfg.penalty.lower, cfg.penalty.upper]))
    assert cfg.describe()["evidence_policy"]["name"] == "reach"


def test_a_steps_time_leaves_out_the_motion_of_its_evidence_actions(monkeypatch):
    from torch_gpioius.exploration import loop

    clock = [0.0]
    monkeypatch.setattr(loop.time, "perf_counter", lambda: clock[0])

    class Slow:                                # a robot whose every move takes 5 s of wall time
        config = "its config"

        def approach(self, direction, max_travel=0.3):
            clock[0] += 5.0
            return "approached"

        def lift(self, direction, **kw):
            clock[0] += 5.0
            raise RuntimeError("refused")

    t = loop._TimedToucher(Slow())
    assert t.approach(None) == "approached" and t.motion == 5.0
    with pytest.raises(RuntimeError):
        t.lift(None)
    assert t.motion == 10.0 and t.config == "its config"          # a refused move's time is motion too
