"""scripts/touch_noise.py: a noise per task is the one-noise model with the outer residuals scaled; checked against a
dense Gaussian process with a noise per task written out here."""

import math

import numpy as np
import pytest
import torch

from tests.scriptfiles import load_script


def _data(seed: int = 0):
    """Contacts on a 10 cm sphere with free space 5 cm out, a cover's seen points 8 mm outside it with free space."""
    rng = np.random.default_rng(seed)

    def sphere(n, r):
        v = rng.standard_normal((n, 3))
        return r * v / np.linalg.norm(v, axis=1, keepdims=True)

    contacts, seen = sphere(30, 0.10), sphere(120, 0.108)
    x = np.concatenate([contacts, contacts * 1.5, seen, seen * (0.158 / 0.108)])
    y = np.concatenate([np.zeros(30), np.ones(30), np.zeros(120), np.ones(120)])
    task = np.concatenate([np.zeros(60, np.int64), np.ones(240, np.int64)])
    return x, y, task


def _dense_mean(x, y, task, kt, kernel, noise_in, noise_out, q):
    """The inner posterior mean at ``q`` of the GP with K_x o K_t and noise ``noise_in`` / ``noise_out`` per task,
    prior mean 1 for both, by one dense solve."""
    xt, qt = torch.as_tensor(x), torch.as_tensor(q)
    t = torch.as_tensor(task)
    g = kernel.value(xt, xt) * kt[t][:, t]
    g = g + torch.diag(torch.where(t == 0, torch.tensor(noise_in), torch.tensor(noise_out)).double())
    weights = torch.linalg.solve(g, torch.as_tensor(y) - 1.0)
    cross = kernel.value(qt, xt) * kt[0, t]
    return (1.0 + cross @ weights).numpy()


def test_a_noise_per_task_is_the_one_noise_model_with_the_outer_residuals_scaled():
    """With K_t' = D K_t D, D = diag(1, lam), lam = sqrt(s_i / s_o), the scaled one-noise model's inner mean
    equals the per-task-noise model's at K_t, to rounding; and its learned K_t is that model's optimum mapped back:
    the marginal likelihoods differ by the constant log|D| only."""
    from torch_gpioius.kernels import Matern52
    from torch_gpioius.models.gpiois import GPIOIS

    script = load_script("touch_noise")
    x, y, task = _data()
    kernel = Matern52(0.05)
    run = GPIOIS(x, y, task, noise=0.08, kernel=Matern52(0.05))
    fitted, lam = script.with_touch_noise(run, x, y, task, 0.02, kernel)
    assert lam == pytest.approx(0.5)
    with pytest.raises(ValueError, match="train_y"):           # the model's label check is back once it is built
        GPIOIS(x, np.where(task == 1, 0.5, y), task, noise=0.08, kernel=Matern52(0.05))
    q = np.random.default_rng(3).uniform(-0.15, 0.15, (50, 3))
    kt_scaled = fitted.task_covariance
    d = torch.diag(torch.tensor([1.0, 1.0 / lam], dtype=torch.float64))
    kt = d @ kt_scaled @ d                                    # the per-task-noise model's K_t: D^-1 K_t' D^-1
    expected = _dense_mean(x, y, task, kt, kernel, 0.02, 0.08, q)
    got = fitted.predict_mean(torch.as_tensor(q), task=0).detach().numpy()
    np.testing.assert_allclose(got, expected, atol=1e-9)

    # the per-task-noise likelihood at the mapped K_t is not beaten by a nearby K_t (the optimum maps across)
    def mll(kt_try):
        t = torch.as_tensor(task)
        g = kernel.value(torch.as_tensor(x), torch.as_tensor(x)) * kt_try[t][:, t]
        g = g + torch.diag(torch.where(t == 0, torch.tensor(0.02), torch.tensor(0.08)).double())
        r = torch.as_tensor(y) - 1.0
        chol = torch.linalg.cholesky(g)
        return float(-0.5 * r @ torch.cholesky_solve(r[:, None], chol)[:, 0] - chol.diagonal().log().sum())

    best = mll(kt)
    for scale in (0.9, 1.1):         # each task's scale moved (S K_t S stays positive semi-definite), then both
        for which in ((scale, 1.0), (1.0, scale), (scale, scale)):
            sc = torch.diag(torch.tensor(which, dtype=torch.float64))
            assert mll(sc @ kt @ sc) <= best + 1e-6


def test_the_touches_trusted_less_than_the_camera_scale_the_outer_labels_up():
    """An inner noise above the camera's scales the outer residuals up (lam > 1, the labels of the paper's form); the
    inner mean matches the dense per-task reference."""
    from torch_gpioius.kernels import Matern52
    from torch_gpioius.models.gpiois import GPIOIS

    script = load_script("touch_noise")
    x, y, task = _data(1)
    kernel = Matern52(0.05)
    run = GPIOIS(x, y, task, noise=0.02, kernel=Matern52(0.05))
    fitted, lam = script.with_touch_noise(run, x, y, task, 0.08, kernel)
    assert lam == pytest.approx(2.0)
    d = torch.diag(torch.tensor([1.0, 1.0 / lam], dtype=torch.float64))
    kt = d @ fitted.task_covariance @ d
    q = np.random.default_rng(4).uniform(-0.15, 0.15, (30, 3))
    np.testing.assert_allclose(fitted.predict_mean(torch.as_tensor(q), task=0).detach().numpy(),
                               _dense_mean(x, y, task, kt, kernel, 0.08, 0.02, q), atol=1e-9)
    assert math.isfinite(fitted.correlation)
