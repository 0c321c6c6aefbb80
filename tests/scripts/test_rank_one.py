"""scripts/rank_one.py: a rank-one K_t makes the inner field an affine image of the outer one, and the similarity
above one is a gap between the seen cover and the inner estimate; checked on a covered sphere."""

import math

import numpy as np
import pytest
import torch

from tests.scriptfiles import load_script

R_IN, GAP = 0.10, 0.008


def _sphere(n: int, r: float, seed: int) -> np.ndarray:
    v = np.random.default_rng(seed).standard_normal((n, 3))
    return r * v / np.linalg.norm(v, axis=1, keepdims=True)


def _covered_sphere():
    """A GPIOIS of contacts on a 10 cm sphere and a camera's view of a cover 8 mm outside it (the upper half), each
    with free space 5 cm out, inside points 2 cm in (the exploration's labels), the defaults' Matérn of 4 cm."""
    from torch_gpioius.kernels import Matern52
    from torch_gpioius.models.gpiois import GPIOIS

    contacts = _sphere(40, R_IN, 0)
    seen = _sphere(300, R_IN + GAP, 1)
    seen = seen[seen[:, 2] > -0.02]
    x = np.concatenate([contacts, contacts * (R_IN + 0.05) / R_IN, contacts * (R_IN - 0.02) / R_IN,
                        seen, seen * (R_IN + GAP + 0.05) / (R_IN + GAP), seen * (R_IN + GAP - 0.02) / (R_IN + GAP)])
    y = np.concatenate([np.zeros(40), np.ones(40), np.full(40, -0.4),
                        np.zeros(len(seen)), np.ones(len(seen)), np.full(len(seen), -0.4)])
    task = np.concatenate([np.zeros(120, np.int64), np.ones(3 * len(seen), np.int64)])
    return GPIOIS(x, y, task, noise=0.08, kernel=Matern52(0.04)).fit(multi_start=True), seen


def test_at_rank_one_the_inner_field_is_the_outer_one_scaled_by_the_similarity():
    """Closed form (docs/theory.md): with K_t = [[a, c], [c, b]], c = sqrt(ab), the posterior means obey
    mu_in - 1 = (mu_out - m_out) / S, S = c / a, at any point, to rounding."""
    model, _ = _covered_sphere()
    a, b = 0.8, 1.1
    model.task_covariance = [[a, math.sqrt(a * b)], [math.sqrt(a * b), b]]
    q = torch.as_tensor(np.random.default_rng(2).uniform(-0.15, 0.15, (200, 3)))
    inner, outer = model.predict_mean(q, task=0), model.predict_mean(q, task=1)
    s = model.similarity
    assert s == pytest.approx(math.sqrt(b / a), rel=1e-12)
    np.testing.assert_allclose((inner - 1.0).numpy(), ((outer - model.outer_mean) / s).numpy(), atol=1e-8)


def _zero_radius(model, dirs: np.ndarray, task: int) -> np.ndarray:
    """`(n,)` the radius [m] along each unit direction where the task's posterior mean crosses zero (bisection)."""
    lo, hi = np.full(len(dirs), 0.05), np.full(len(dirs), 0.16)
    for _ in range(50):
        mid = (lo + hi) / 2
        inside = model.predict_mean(torch.as_tensor(dirs * mid[:, None]), task=task).detach().numpy() < 0
        lo, hi = np.where(inside, mid, lo), np.where(inside, hi, mid)
    return (lo + hi) / 2


def test_the_gap_a_rank_one_similarity_implies_is_where_the_inner_estimate_lies_and_held_off_the_likelihood_drops():
    """The learned K_t of a uniformly covered sphere is rank one with a similarity above one; the gap it implies at
    the seen points (first order in the outer field's slope) is their distance from the model's own inner zero set
    along the radius (found by bisection) to a millimetre, and of the cover's size; held at lower correlations by the
    profile likelihood, K_t has exactly that correlation and a likelihood no higher."""
    rank_one = load_script("rank_one")
    model, seen = _covered_sphere()
    assert model.correlation > 0.999 and model.similarity > 1.0
    implied = rank_one.implied_gap(model, seen)
    r = np.linalg.norm(seen, axis=1)
    to_inner = float(np.median(r - _zero_radius(model, seen / r[:, None], 0)))
    assert implied == pytest.approx(to_inner, abs=0.001) and 0.002 < implied < 0.016
    _, f_hat = rank_one.held_at(model, min(model.correlation, 1.0))
    for rho in (0.98, 0.9, 0.7):
        kt, f = rank_one.held_at(model, rho)
        assert float(kt[0, 1] / torch.sqrt(kt[0, 0] * kt[1, 1])) == pytest.approx(rho, abs=1e-12)
        assert f <= f_hat + 1e-9
