import numpy as np
import torch

from torch_gpioius import InverseMultiquadricKernel
from tests.reference import imq


def test_values_match_formula():
    rng = np.random.default_rng(0)
    a, b = rng.normal(size=(7, 3)), rng.normal(size=(5, 3))
    k = InverseMultiquadricKernel(lengthscale=0.15)
    got = k(torch.tensor(a), torch.tensor(b)).to_dense().numpy()
    expected = (((a[:, None] - b[None]) ** 2).sum(-1) + 0.15**2) ** -0.5
    np.testing.assert_allclose(got, expected, rtol=1e-13)
    np.testing.assert_allclose(got, imq(a, b, 0.15), rtol=1e-13)
    assert abs(got.max() - 1 / 0.15) < 1 / 0.15  # sanity: bounded by 1/theta
    assert np.isclose(k(torch.zeros(1, 3, dtype=torch.float64)).to_dense().item(), 1 / 0.15)


def test_diag_and_batch():
    k = InverseMultiquadricKernel(lengthscale=0.1, batch_shape=torch.Size([4]))
    x = torch.randn(4, 6, 2, dtype=torch.float64)
    full = k(x).to_dense()
    assert full.shape == (4, 6, 6)
    diag = k(x, diag=True)
    assert diag.shape == (4, 6)
    torch.testing.assert_close(diag, torch.diagonal(full, dim1=-2, dim2=-1))
    x2 = torch.randn(4, 6, 2, dtype=torch.float64)
    d12 = k(x, x2, diag=True)
    torch.testing.assert_close(d12, torch.diagonal(k(x, x2).to_dense(), dim1=-2, dim2=-1))


def test_theta_fixed_by_default_and_learnable_on_request():
    assert not InverseMultiquadricKernel(0.1).raw_theta.requires_grad
    k = InverseMultiquadricKernel(0.1, learn_lengthscale=True)
    assert k.raw_theta.requires_grad
    assert abs(float(k.theta.detach()) - 0.1) < 1e-12
    k.theta = 0.3
    assert abs(float(k.theta.detach()) - 0.3) < 1e-12


def test_bad_lengthscale_and_the_theta_alias():
    import pytest
    with pytest.raises(ValueError, match="lengthscale"):
        InverseMultiquadricKernel(lengthscale=-1.0)
    with pytest.warns(DeprecationWarning, match=r"InverseMultiquadricKernel\(theta=...\) is .*lengthscale"):
        k = InverseMultiquadricKernel(theta=0.12)
    assert k.length == 0.12 and float(k.lengthscale) == pytest.approx(0.12, rel=1e-15)
    assert k.describe() == {"kernel": "InverseMultiquadric", "lengthscale": 0.12}
    from torch_gpioius.kernels import from_description

    old = from_description({"kernel": "InverseMultiquadric", "theta": 0.12})        # a description of before
    assert old.describe() == k.describe() and repr(old) == "InverseMultiquadricKernel(lengthscale=0.12)"


from torch_gpioius.testing import KernelContract  # noqa: E402


class TestContract(KernelContract):
    def make(self):
        return InverseMultiquadricKernel(lengthscale=0.12)
