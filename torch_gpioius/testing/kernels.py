"""The kernel contract's tests: every kernel must pass them (a kernel's test file subclasses :class:`KernelContract`,
the project's own and a user's alike).

What the exact engines rely on (:mod:`torch_gpioius.kernels.base`), checked against independent references: ``value``
against GPyTorch's ``forward`` and against itself under shifts (stationarity), ``gradient`` against autograd,
``prior_variance`` against the diagonal, ``second_derivative_at_zero`` against a Richardson-extrapolated second
difference of the radial profile, Gram matrices positive definite, and ``describe`` rebuilding the same kernel.
A kernel with a learnable length (hyper-parameter learning) also passes the gradient checks in its length:
``value_at`` at the kernel's own length is ``value``, its autograd derivative in the length matches a Richardson
difference, setting ``length`` round-trips exactly and moves ``describe``, and GPyTorch's ``forward`` carries the
gradient to the registered parameter.
"""

from __future__ import annotations

import numpy as np
import torch

from ..kernels import from_description
from .differences import richardson_derivative

__all__ = ["KernelContract"]


class KernelContract:
    """pytest checks of the kernel contract: subclass it in a test file as ``class TestMyKernel(KernelContract)``
    with ``make()`` returning the kernel under test (and ``dim`` if not 3); pytest runs each ``test_*`` method.

    Example:
        >>> class TestMatern52(KernelContract):
        ...     def make(self):
        ...         return torch_gpioius.kernels.Matern52(0.1)
    """

    dim = 3

    def make(self):
        raise NotImplementedError

    def _points(self, n, seed=0, scale=0.2):
        rng = np.random.default_rng(seed)
        return torch.tensor(rng.uniform(-scale, scale, (n, self.dim)))

    def test_value_is_gpytorch_forward_and_stationary(self):
        k = self.make()
        a, b = self._points(7), self._points(5, seed=1)
        v = k.value(a, b)
        assert v.shape == (7, 5) and v.dtype == torch.float64
        torch.testing.assert_close(k(a, b).to_dense(), v, rtol=1e-14, atol=0.0)
        shift = torch.tensor([0.3, -0.1, 0.05][: self.dim], dtype=torch.float64)
        torch.testing.assert_close(k.value(a + shift, b + shift), v, rtol=1e-12, atol=1e-14)
        torch.testing.assert_close(k.value(b, a), v.T, rtol=1e-14, atol=0.0)

    def test_prior_variance_is_the_diagonal(self):
        k = self.make()
        a = self._points(4)
        diag = torch.diagonal(k.value(a, a))
        torch.testing.assert_close(diag, torch.full_like(diag, float(k.prior_variance(1.0))), rtol=1e-14, atol=0.0)
        assert float(k.prior_variance(2.5)) == float(2.5 * k.prior_variance(1.0)) or abs(
            float(k.prior_variance(2.5)) - 2.5 * float(k.prior_variance(1.0))) < 1e-14 * float(k.prior_variance(2.5))

    def test_gradient_matches_autograd(self):
        k = self.make()
        a, b = self._points(6), self._points(4, seed=2)
        b = torch.cat([b, a[:1]])                           # a coincident pair: the gradient at r = 0
        g = k.gradient(a, b)
        assert g.shape == (self.dim, 6, 5)
        ref = torch.zeros_like(g)
        for j in range(b.shape[0]):
            aa = a.clone().requires_grad_(True)
            (grad,) = torch.autograd.grad(k.value(aa, b[j:j + 1]).sum(), aa)
            ref[:, :, j] = grad.T
        torch.testing.assert_close(g, ref, rtol=1e-10, atol=1e-12 * float(k.prior_variance(1.0)))

    def test_second_derivative_at_zero_matches_a_difference(self):
        k = self.make()
        x = torch.zeros(1, self.dim, dtype=torch.float64)
        e = torch.zeros(1, self.dim, dtype=torch.float64)
        e[0, 0] = 1.0

        def first(r):          # kappa'(r) along e, itself by a central difference of small step
            return richardson_derivative(lambda s: float(k.value(x + float(s) * e, x)), np.array(r), 1e-4)[0][0]

        est, err = richardson_derivative(lambda r: first(float(r)), np.array(0.0), 1e-3)
        want = k.second_derivative_at_zero()
        assert abs(float(est[0]) - want) <= 10 * float(err[0]) + 1e-6 * abs(want), (float(est[0]), want)

    def test_gram_matrices_are_positive_definite(self):
        k = self.make()
        a = self._points(80, seed=3)
        eig = torch.linalg.eigvalsh(k.value(a, a))
        assert float(eig.min()) > -1e-12 * float(eig.max())

    # ------------------------------------------------------------------ the learnable length
    def _learnable(self):
        import pytest

        k = self.make()
        if not getattr(k, "learnable_length", False):
            pytest.skip("this kernel has no learnable length")
        return k

    def test_value_at_its_own_length_is_value(self):
        k = self._learnable()
        a, b = self._points(6), self._points(4, seed=5)
        length = torch.tensor(k.length, dtype=torch.float64)
        torch.testing.assert_close(k.value_at(a, b, length), k.value(a, b), rtol=1e-15, atol=0.0)

    def test_gradient_in_the_length_matches_a_difference(self):
        k = self._learnable()
        a, b = self._points(5), self._points(4, seed=6)
        b = torch.cat([b, a[:1]])                           # r = 0 too: the derivative of the prior variance
        weights = torch.tensor(np.random.default_rng(7).standard_normal((5, 5)))
        length = torch.tensor(k.length, dtype=torch.float64, requires_grad=True)
        (grad,) = torch.autograd.grad((k.value_at(a, b, length) * weights).sum(), length)
        est, err = richardson_derivative(
            lambda ell: float((k.value_at(a, b, torch.tensor(float(ell), dtype=torch.float64)) * weights).sum()),
            np.array(k.length), 1e-3 * k.length)
        assert abs(float(grad) - float(est[0])) <= 10 * float(err[0]) + 1e-9 * abs(float(grad)), (float(grad), est)

    def test_length_round_trips_and_is_described(self):
        import pytest

        k = self._learnable()
        before = k.describe()
        k.length = 0.0731          # through the parameter's constraint and back: to rounding (a softplus is not exact)
        assert abs(k.length - 0.0731) <= 4e-16 * 0.0731
        assert k.describe() != before
        again = from_description(k.describe())
        assert abs(again.length - k.length) <= 4e-16 * k.length
        for bad in (0.0, -0.1, float("nan"), float("inf")):
            with pytest.raises(ValueError):
                k.length = bad
        assert abs(k.length - 0.0731) <= 4e-16 * 0.0731      # a refused value leaves the kernel as it was

    def test_forward_is_differentiable_in_its_parameter(self):
        k = self._learnable()
        a = self._points(5)
        params = [p for p in k.parameters()]
        assert params, "a learnable length lives in a registered torch parameter"
        for p in params:
            p.requires_grad_(True)
        try:
            out = k(a, a).to_dense().sum()
            grads = torch.autograd.grad(out, params, allow_unused=True)
        finally:
            for p in params:
                p.requires_grad_(False)
        assert any(g is not None and bool(torch.isfinite(g).all()) and float(g.abs().sum()) > 0 for g in grads)

    def test_describe_rebuilds_the_same_kernel(self):
        k = self.make()
        again = from_description(k.describe())
        a, b = self._points(5), self._points(3, seed=4)
        torch.testing.assert_close(again.value(a, b), k.value(a, b), rtol=0.0, atol=0.0)
