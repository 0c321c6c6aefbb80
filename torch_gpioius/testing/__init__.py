"""What users need to test their own extensions as the project tests its own: :class:`KernelContract` (the checks
every kernel the exact engines use must pass) and the finite-difference references it checks against.

A kernel of one's own is tested by subclassing the contract in a pytest file::

    from torch_gpioius.testing import KernelContract

    class TestMyKernel(KernelContract):
        def make(self):
            return MyKernel(lengthscale=0.1)

The project's kernels also pass GPyTorch's own ``gpytorch.test.base_kernel_test_case.BaseKernelTestCase``
(``tests/kernels/test_gpytorch_contract.py`` shows how, with float64 as the default dtype).
"""

from .differences import assert_close_to_reference, richardson_derivative
from .kernels import KernelContract

__all__ = ["KernelContract", "richardson_derivative", "assert_close_to_reference"]
