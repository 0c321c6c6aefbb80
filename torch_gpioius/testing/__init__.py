"""What users need to test their own extensions as the project tests its own: :class:`KernelContract` (the checks
every kernel the exact engines use must pass), :class:`WorldContract` (what the exploration, the studies and the logs
rely on of a world) and the finite-difference references they check against.

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
from .worlds import WorldContract

__all__ = ["KernelContract", "WorldContract", "richardson_derivative", "assert_close_to_reference"]
