import numpy as np
import torch

import torch_gpioius as tg
from tests import reference as ref
from torch_gpioius.geometry import surface_geometry


def _circle_model(task_model=False):
    a = np.linspace(0, 2 * np.pi, 30, endpoint=False)
    ring = np.stack([np.cos(a), np.sin(a)], -1)
    x = np.concatenate([0.2 * ring, 0.3 * ring])
    y = np.concatenate([np.zeros(30), np.ones(30)])
    if task_model:
        t = np.r_[np.zeros(15), np.ones(15), np.zeros(15), np.ones(15)].astype(np.int64)
        return tg.GPIOIS(torch.tensor(x), torch.tensor(y), torch.tensor(t),
                         task_covariance=torch.tensor([[0.9, 0.4], [0.4, 1.1]]))
    return tg.GPIS(torch.tensor(x), torch.tensor(y))


def _fd(model, x, task, which, h=1e-3):
    """Per-point gradients of the posterior mean (which=0) or variance (1) with their error estimates."""
    grads, errs = np.zeros_like(x), np.zeros_like(x)
    for i in range(len(x)):
        f = lambda p: float(tg.geometry.predict_task(model, torch.tensor(p[None]), task)[which])  # noqa: E731
        grads[i], errs[i] = ref.richardson_derivative(f, x[i], h)
    return grads, errs


def test_gradients_match_central_differences():
    rng = np.random.default_rng(0)
    x = rng.uniform(-0.35, 0.35, (15, 2))
    for model, task in [(_circle_model(), 0), (_circle_model(True), 0), (_circle_model(True), 1)]:
        g = surface_geometry(model, torch.tensor(x), task)
        ref.assert_close_to_reference(g.grad_mean.numpy(), *_fd(model, x, task, 0), what="grad mu")
        ref.assert_close_to_reference(g.grad_var.numpy(), *_fd(model, x, task, 1), what="grad V")


def test_normals_and_projector_on_circle():
    model = _circle_model()
    a = np.linspace(0, 2 * np.pi, 13)
    radial = np.stack([np.cos(a), np.sin(a)], -1)
    g = surface_geometry(model, torch.tensor(0.2 * radial))
    n = g.normal.numpy()
    np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1.0, atol=1e-12)
    assert (np.einsum("ij,ij->i", n, radial) > 0.999).all()  # outward, radial
    p = g.projector.numpy()
    np.testing.assert_allclose(np.einsum("kij,kj->ki", p, n), 0.0, atol=1e-12)   # P n = 0
    np.testing.assert_allclose(p @ p, p, atol=1e-12)                             # idempotent
    assert g.normal_defined.all()


def test_undefined_normal_is_flagged_not_nan():
    model = tg.GPIS(torch.tensor([[0.0, 0.0]]), torch.tensor([0.0]))
    g = surface_geometry(model, torch.tensor([[0.0, 0.0]]))  # gradient exactly 0 at the single datum
    assert not g.normal_defined[0]
    assert torch.equal(g.normal[0], torch.zeros(2))
    assert torch.equal(g.projector[0], torch.eye(2, dtype=torch.float64))
