"""Independent dense float64 reference of eq. (2)-(3), (5), (9)-(13) and (16) in plain NumPy.

No GPyTorch, no torch_gpioius code in the formulas: the tests hold the library against them
(:func:`assert_model_predicts` is the one helper that calls a model).
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


def posterior_with_means(x, y, task, kt, theta, noise, xq, tq, mx, mq):
    """Eq. (12)-(13) with a prior mean per observation ``mx`` `(n,)` and per query ``mq`` `(m,)` (a mean that varies
    over space, such as the outer task's gap field)."""
    g = gram(x, task, kt, theta, noise)
    kq = imq(xq, x, theta) * kt[tq, task][None, :]
    mean = mq + kq @ np.linalg.solve(g, y - mx)
    var = kt[tq, tq] / theta - np.einsum("ij,ji->i", kq, np.linalg.solve(g, kq.T))
    return mean, var


def mll_with_means(x, y, task, kt, theta, noise, mx):
    """Eq. (16) with a prior mean per observation ``mx`` `(n,)`."""
    g = gram(x, task, kt, theta, noise)
    r = y - mx
    sign, logdet = np.linalg.slogdet(g)
    assert sign > 0
    return -0.5 * logdet - 0.5 * r @ np.linalg.solve(g, r) - 0.5 * len(x) * np.log(2 * np.pi)


def gap_field(points, gaps, length, scale, noise, prior, xq):
    """The GP regression mean of a scalar over space: ``prior + k(xq, P) (K + noise^2 I)^-1 (gaps - prior)``,
    ``k = scale^2 exp(-|x - x'|^2 / (2 length^2))``."""
    def k(a, b):
        return scale ** 2 * np.exp(-0.5 * ((a[:, None, :] - b[None, :, :]) ** 2).sum(-1) / length ** 2)

    alpha = np.linalg.solve(k(points, points) + noise ** 2 * np.eye(len(points)), gaps - prior)
    return prior + k(xq, points) @ alpha


def gap_field_mll(points, gaps, length, scale, noise, prior):
    """The log marginal likelihood of ``gaps`` under that regression."""
    g = scale ** 2 * np.exp(-0.5 * ((points[:, None, :] - points[None, :, :]) ** 2).sum(-1) / length ** 2) \
        + noise ** 2 * np.eye(len(points))
    r = gaps - prior
    return -0.5 * np.linalg.slogdet(g)[1] - 0.5 * r @ np.linalg.solve(g, r) - 0.5 * len(r) * np.log(2 * np.pi)


def kt_from_chol(phi):
    u, v, w = phi
    lo = np.array([[np.exp(u), 0.0], [v, np.exp(w)]])
    return lo @ lo.T


# the finite differences live in the package, where users' own kernel tests find them too
from torch_gpioius.testing.differences import assert_close_to_reference, richardson_derivative  # noqa: E402,F401


def assert_model_predicts(model, xq, task, mean, var, atol=1e-8):
    """``model``'s posterior of ``task`` at ``xq`` `(m, d)` by every route it has (``predict``, ``predict_mean``,
    the engine's closed form where it has one, GPyTorch's eval-mode call) equals the reference ``mean``, ``var``;
    returns the closed form's output (None without one). The one place the tests call the library here."""
    import torch

    q = torch.tensor(xq)
    got_mean, got_var = model.predict(q, task=task)
    np.testing.assert_allclose(got_mean.numpy(), mean, atol=atol, rtol=0)
    np.testing.assert_allclose(got_var.numpy(), var, atol=atol, rtol=0)
    np.testing.assert_allclose(model.predict_mean(q, task).detach().numpy(), mean, atol=atol, rtol=0)
    closed = model._predict_with_gradients(q, task)
    if closed is not None:
        np.testing.assert_allclose(closed[0].numpy(), mean, atol=atol, rtol=0)
    with torch.no_grad():
        post = model.eval()(q, task)
    model.train()
    np.testing.assert_allclose(post.mean.numpy(), mean, atol=atol, rtol=0)
    return closed
