import math

import numpy as np
import pytest
import torch

import torch_gpioius as tg
from tests import reference as ref
from torch_gpioius.exploration.planning import RangePenalty, ZeroPenalty, plan_direction


def _half_circle_model():
    """Circle r = 0.2 touched on its upper half only: variance is higher on the lower half."""
    a = np.linspace(0.0, math.pi, 25)
    ring = np.stack([np.cos(a), np.sin(a)], -1)
    x = np.concatenate([0.2 * ring, 0.3 * ring])
    y = np.r_[np.zeros(25), np.ones(25)]
    return tg.GPIS(torch.tensor(x), torch.tensor(y))


def test_direction_is_tangent_unit_alpha_and_climbs_variance():
    model = _half_circle_model()
    x = torch.tensor([0.2, 0.0], dtype=torch.float64)   # right end of the touched arc
    plan = plan_direction(model, x, step=0.01)
    d = plan.direction
    assert float(d.norm()) == pytest.approx(0.01, rel=1e-12)
    assert abs(float(d @ plan.normal)) < 1e-12                # tangent (P d = d)
    # the normal is (close to) radial and the step heads into the untouched lower half
    assert float(plan.normal @ torch.tensor([1.0, 0.0], dtype=torch.float64)) > 0.95
    assert float(d[1]) < 0
    # variance really increases along d (finite step, independent of the gradient code)
    v0 = model.predict(x[None])[1]
    v1 = model.predict((x + 0.2 * d)[None])[1]
    assert float(v1) > float(v0)
    assert plan.fallback == ""


def test_direction_matches_eq19_computed_independently():
    model = _half_circle_model()
    x = torch.tensor([[0.15, 0.12]], dtype=torch.float64)
    # independent: finite-difference gradients of mu and V (with their error estimates), projector, eq. (19)
    fd = [ref.richardson_derivative(lambda p: float(model.predict(torch.tensor(p[None]))[which]), x[0].numpy(), 1e-3)
          for which in (0, 1)]
    (g_mu, e_mu), (g_v, e_v) = fd
    n = g_mu / np.linalg.norm(g_mu)
    pg = (np.eye(2) - np.outer(n, n)) @ g_v
    expected = 0.01 * pg / np.linalg.norm(pg)
    got = plan_direction(model, x[0], step=0.01).direction.numpy()
    angle = math.acos(min(1.0, float(got @ expected) / 1e-4))
    # first-order error of the reference direction: the normal's error rotates P, the gradient's error tilts pg
    bound = (np.linalg.norm(e_v) + np.linalg.norm(g_v) * np.linalg.norm(e_mu) / np.linalg.norm(g_mu)) \
        / np.linalg.norm(pg)
    assert angle <= 10 * bound + 1e-12, (angle, bound)


def test_degenerate_cases_are_deterministic():
    # a single datum: grad mu = 0 at the datum (undefined normal), grad V = 0 there too
    model = tg.GPIS(torch.tensor([[0.0, 0.0]]), torch.tensor([0.0]))
    plan = plan_direction(model, torch.tensor([0.0, 0.0]), step=0.01)
    assert plan.fallback != ""
    assert float(plan.direction.norm()) == pytest.approx(0.01)
    again = plan_direction(model, torch.tensor([0.0, 0.0]), step=0.01)
    assert torch.equal(plan.direction, again.direction)
    prev = torch.tensor([0.0, 1.0], dtype=torch.float64)
    with_prev = plan_direction(model, torch.tensor([0.0, 0.0]), step=0.01, previous=prev)
    assert with_prev.fallback == "previous-direction"
    torch.testing.assert_close(with_prev.direction, 0.01 * prev)


def test_range_penalty_eq25():
    c = RangePenalty([-1.0, -1.0], [1.0, 1.0], beta=100.0)
    x = torch.tensor([[0.0, 0.0], [1.5, 0.0], [2.0, 3.0]], dtype=torch.float64)
    torch.testing.assert_close(c(x), torch.tensor([0.0, -100 * 0.25, -100 * (1.0 + 4.0)], dtype=torch.float64))
    torch.testing.assert_close(c.distance(x), torch.tensor([0.0, 0.5, math.sqrt(5.0)], dtype=torch.float64))
    assert float(ZeroPenalty()(x).abs().sum()) == 0.0


def test_range_penalty_steers_back_into_the_box():
    model = _half_circle_model()
    x = torch.tensor([0.2, 0.0], dtype=torch.float64)
    free = plan_direction(model, x, step=0.01)
    # forbid everything below y = 0.05: the penalty gradient now dominates and pushes the step upwards
    boxed = plan_direction(model, x + torch.tensor([0.0, -0.1], dtype=torch.float64) * 0, step=0.01,
                           penalty=RangePenalty([-1.0, 0.05], [1.0, 1.0]))
    assert float(free.direction[1]) < 0 < float(boxed.direction[1])


def test_a_measured_normal_far_from_the_estimate_rules_the_tangent_plane():
    """Where the estimate's normal is 100 degrees off the measured contact normal (a fingertip under an object the
    model has wrong), the step is projected onto the measured tangent plane: it never points into the object,
    whatever the variance gradient and the range penalty ask. Within 60 degrees the estimate's plane is kept."""
    model = _half_circle_model()
    x = torch.tensor([0.2, 0.0], dtype=torch.float64)
    plain = plan_direction(model, x, step=0.01)
    n_est = plain.normal / plain.normal.norm()
    turn = math.radians(100.0)
    rot = torch.tensor([[math.cos(turn), -math.sin(turn)], [math.sin(turn), math.cos(turn)]], dtype=torch.float64)
    measured = rot @ n_est
    # a penalty whose gradient points straight into the object along the measured normal
    push = lambda p: 10.0 * (p @ measured)                                       # noqa: E731
    plan = plan_direction(model, x, step=0.01, penalty=push, measured_normal=measured)
    assert plan.fallback.startswith("measured-normal")
    assert abs(float(plan.direction @ measured)) < 1e-15                          # in the measured tangent plane
    assert float(plan.direction.norm()) == pytest.approx(0.01, rel=1e-12)
    near = rot.new_tensor([[math.cos(0.5), -math.sin(0.5)], [math.sin(0.5), math.cos(0.5)]]) @ n_est   # 29 deg
    kept = plan_direction(model, x, step=0.01, measured_normal=near)
    assert kept.fallback == "" and torch.equal(kept.direction, plain.direction)
    for bad in (torch.tensor([float("nan"), 0.0], dtype=torch.float64), torch.zeros(2, dtype=torch.float64)):
        assert torch.equal(plan_direction(model, x, step=0.01, measured_normal=bad).direction, plain.direction)


@pytest.mark.parametrize("step", [float("nan"), 0.0, -0.01, float("inf"), "0.01", True, 5.0])
def test_a_step_that_is_no_length_is_refused(step):
    """Issue 33, item 10: step=nan returned a NaN direction and step=0 a zero one."""
    import torch_gpioius as tg

    x = torch.tensor([[0.1, 0.0], [0.0, 0.1], [-0.1, 0.0], [0.0, -0.1], [0.2, 0.0]], dtype=torch.float64)
    model = tg.GPIS(
        x,
        torch.tensor([0.0, 0.0, 0.0, 0.0, 1.0], dtype=torch.float64),
        kernel=tg.kernels.InverseMultiquadricKernel(0.1),
        noise=0.006,
    )
    with pytest.raises(ValueError, match="step: "):
        plan_direction(model, x[0], step=step)
