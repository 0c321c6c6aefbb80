"""Independent dense float64 reference of eq. (2)-(3), (5), (9)-(13) and (16) in plain NumPy.

No GPyTorch, no torch_gpioius code: the tests hold the library against these formulas.
"""

import numpy as np


def imq(a, b, theta):
    d2 = ((a[:, None, :] - b[None, :, :]) ** 2).sum(-1)
    return 1.0 / np.sqrt(d2 + theta**2)


def gram(x, task, kt, theta, noise):
    return imq(x, x, theta) * kt[np.ix_(task, task)] + noise * np.eye(len(x))


def _means(m, task):
    """The prior mean of each observation: ``m`` one constant, or a constant per task ``(m_0, m_1)``."""
    m = np.asarray(m, dtype=float)
    return m if m.ndim == 0 else m[task]


def posterior(x, y, task, kt, theta, noise, xq, tq, m=1.0):
    """Eq. (12)-(13): mean and variance of F_tq at xq (``m``: the prior mean, or one per task)."""
    g = gram(x, task, kt, theta, noise)
    kq = imq(xq, x, theta) * kt[tq, task][None, :]
    mean = _means(m, tq) + kq @ np.linalg.solve(g, y - _means(m, task))
    var = kt[tq, tq] / theta - np.einsum("ij,ji->i", kq, np.linalg.solve(g, kq.T))
    return mean, var


def mll(x, y, task, kt, theta, noise, m=1.0):
    """Eq. (16) with C = -n/2 log(2 pi) (``m``: the prior mean, or one per task)."""
    g = gram(x, task, kt, theta, noise)
    r = y - _means(m, task)
    sign, logdet = np.linalg.slogdet(g)
    assert sign > 0
    return -0.5 * logdet - 0.5 * r @ np.linalg.solve(g, r) - 0.5 * len(x) * np.log(2 * np.pi)


def kt_from_chol(phi):
    u, v, w = phi
    lo = np.array([[np.exp(u), 0.0], [v, np.exp(w)]])
    return lo @ lo.T


# the finite differences live in the package, where users' own kernel tests find them too
from torch_gpioius.testing.differences import assert_close_to_reference, richardson_derivative  # noqa: E402,F401
