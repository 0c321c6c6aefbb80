"""The truncated outer basis (inference.lowrank): its residual and its dropped-trace bound against dense algebra."""

import numpy as np
import pytest
import torch

from torch_gpioius.inference.lowrank import pivoted_cholesky, truncated_basis
from torch_gpioius.kernels import InverseMultiquadricKernel


def _cloud(n=500, seed=0):
    rng = np.random.default_rng(seed)
    v = rng.normal(size=(n, 3))
    return torch.tensor(v / np.linalg.norm(v, axis=1, keepdims=True) * np.array([0.25, 0.18, 0.3]))


@pytest.mark.parametrize("trace_tol", [1e-1, 1e-4, 1e-8])
def test_residual_is_psd_and_its_trace_bounds_it(trace_tol):
    x, kernel = _cloud(), InverseMultiquadricKernel(0.15)
    factor, resid, piv = pivoted_cholesky(kernel, x, trace_tol)
    k = kernel.value(x, x)
    e = k - factor @ factor.T
    ev = torch.linalg.eigvalsh(e)
    rounding = 1e-13 * len(x) * float(k.diagonal().max())
    assert float(ev.min()) >= -rounding                               # a Schur complement: PSD to rounding
    assert float(resid.sum()) <= trace_tol
    torch.testing.assert_close(resid, e.diagonal().clamp_min(0), rtol=0, atol=1e-12)
    assert float(ev.max()) <= float(resid.sum()) + rounding           # ||E||_2 <= tr(E)
    assert len(set(piv.tolist())) == len(piv) == factor.shape[1]      # distinct pivots, one per column
    assert bool((resid[piv] == 0).all())


def test_rank_grows_as_the_tolerance_shrinks_and_the_basis_reproduces_the_factor():
    x, kernel = _cloud(1500, seed=1), InverseMultiquadricKernel(0.15)
    ranks = [truncated_basis(kernel, x, t).rank for t in (1.0, 1e-3, 1e-6)]
    assert ranks[0] < ranks[1] < ranks[2] <= len(x)
    basis = truncated_basis(kernel, x, 1e-6)
    factor, resid, _ = pivoted_cholesky(kernel, x, 1e-6)
    kp = (basis.u * basis.lam) @ basis.u.T
    weak = basis.dropped_trace - float(resid.sum())        # modes below 1e-12 lam_max, dropped and counted
    assert 0 <= weak < 1e-6
    assert float((kp - factor @ factor.T).abs().max()) <= weak + 1e-11
    k = kernel.value(x, x)
    assert float(torch.trace(k - kp)) <= basis.dropped_trace + 1e-10
    assert basis.dropped_trace <= 1e-6
    # the strong modes are orthonormal (the weak ones only to eps lam_max / lam_k, module docstring)
    strong = basis.lam > 1e-6 * float(basis.lam.max())
    gram = basis.u[:, strong].T @ basis.u[:, strong]
    torch.testing.assert_close(gram, torch.eye(int(strong.sum()), dtype=torch.float64), rtol=0, atol=1e-9)


def test_bad_tolerance_is_refused():
    x, kernel = _cloud(20), InverseMultiquadricKernel(0.15)
    for bad in (-1.0, float("nan"), float("inf")):
        with pytest.raises(ValueError, match="trace_tol"):
            pivoted_cholesky(kernel, x, bad)
