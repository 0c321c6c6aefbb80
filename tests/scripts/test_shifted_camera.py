"""scripts/shifted_camera.py: the inner task's leave-one-out densities against refits without each observation, and
the camera's observations of a cover moved onto the body by the gap the contacts measure (a covered sphere)."""

import math

import numpy as np
import torch

from tests.scriptfiles import load_script

R_IN, GAP = 0.10, 0.03


def _sphere(n: int, r: float, seed: int) -> np.ndarray:
    v = np.random.default_rng(seed).standard_normal((n, 3))
    return r * v / np.linalg.norm(v, axis=1, keepdims=True)


def _covered(n_seen: int = 200):
    """Contacts on a 10 cm sphere with free space 5 cm out; a camera's view of a cover 3 cm off it (the upper half)
    with free space 5 cm out: the observations, labelled as the exploration labels them."""
    contacts = _sphere(30, R_IN, 0)
    seen = _sphere(n_seen, R_IN + GAP, 1)
    seen = seen[seen[:, 2] > -0.02]
    r_out = R_IN + GAP
    x_in = np.concatenate([contacts, contacts * (R_IN + 0.05) / R_IN])
    y_in = np.r_[np.zeros(len(contacts)), np.ones(len(contacts))]
    x_out = np.concatenate([seen, seen * (r_out + 0.05) / r_out])
    y_out = np.r_[np.zeros(len(seen)), np.ones(len(seen))]
    return contacts, x_in, y_in, x_out, y_out


def test_leave_one_out_densities_match_refits_without_each_observation():
    """The closed form (one inverse) against the posterior of the data without observation i, solved afresh, at the
    same hyperparameters: the predictive density of its label, sigma^2 included."""
    from torch_gpioius.kernels import Matern52
    from torch_gpioius.models.gpiois import GPIOIS

    script = load_script("shifted_camera")
    _, x_in, y_in, x_out, y_out = _covered(40)
    model = GPIOIS(np.r_[x_in, x_out], np.r_[y_in, y_out],
                   np.r_[np.zeros(len(y_in), np.int64), np.ones(len(y_out), np.int64)], noise=0.05,
                   kernel=Matern52(0.05)).fit(multi_start=True)
    model.set_outer_mean(0.8)                       # a task mean other than 1: each label less its own task's
    got = script.inner_loo(model)
    x = torch.as_tensor(np.r_[x_in, x_out])
    y = torch.as_tensor(np.r_[y_in, y_out])
    task = torch.as_tensor(np.r_[np.zeros(len(y_in), np.int64), np.ones(len(y_out), np.int64)])
    kt = model.task_covariance.detach()
    gram = model.covar_module.value(x, x).detach() * kt[task][:, task]
    gram = gram + float(model.noise) * torch.eye(len(y), dtype=x.dtype)
    residual = y - torch.where(task == 0, torch.ones_like(y), torch.full_like(y, 0.8))
    want = []
    for i in range(len(y_in)):
        keep = torch.arange(len(y)) != i
        weights = torch.linalg.solve(gram[keep][:, keep], gram[keep, i])
        mean = float(weights @ residual[keep])
        var = float(gram[i, i] - weights @ gram[keep, i])
        want.append(-0.5 * math.log(2 * math.pi * var) - 0.5 * (float(residual[i]) - mean) ** 2 / var)
    assert got.shape == (len(y_in),)
    # two routes through one Gram matrix: each loses about its condition number times the unit roundoff
    tol = 100 * float(torch.linalg.cond(gram)) * torch.finfo(torch.float64).eps
    np.testing.assert_allclose(got, want, rtol=0, atol=tol)


def test_the_camera_moved_by_the_contacts_gap_lies_on_the_body():
    """A cover 3 cm off a 10 cm sphere: the contacts measure a gap of 3 cm (to the camera GPIS's surface, within its
    chords' and the fit's error) and the seen points moved by it lie at the body's radius."""
    from torch_gpioius.kernels import Matern52

    script = load_script("shifted_camera")
    contacts, _, _, x_out, y_out = _covered()
    bounds = np.array([[-0.2, -0.2, -0.2], [0.2, 0.2, 0.2]])
    moved, gap = script.shifted_camera(x_out, y_out, contacts[contacts[:, 2] > 0.02], Matern52(0.05), 0.01, bounds)
    assert abs(gap - GAP) < 0.004
    radius = np.linalg.norm(moved[y_out == 0], axis=1)
    assert abs(np.median(radius) - R_IN) < 0.004
    assert np.all(np.abs(np.linalg.norm(x_out[y_out == 0], axis=1) - np.linalg.norm(moved[y_out == 0], axis=1)
                         - gap) < 0.01)                                   # each moved inward by about the gap
