"""The project's kernels pass GPyTorch's own kernel test case (``BaseKernelTestCase``: batches, ``active_dims``,
``diag``, indexing a batch of kernels, pickling, dtype and device moves), beside the project's contract
(:class:`torch_gpioius.testing.KernelContract`).

GPyTorch's case expects a kernel in the default dtype; the project computes in float64 (its kernels are built in
float64), so each test runs with float64 as the default and restores the default after.
"""

import unittest

import torch
from gpytorch.test.base_kernel_test_case import BaseKernelTestCase

from torch_gpioius.kernels import InverseMultiquadricKernel, Matern52


class _Float64Default:
    def setUp(self):
        self._default_dtype = torch.get_default_dtype()
        torch.set_default_dtype(torch.float64)
        super().setUp()

    def tearDown(self):
        super().tearDown()
        torch.set_default_dtype(self._default_dtype)


class TestInverseMultiquadricInGPyTorchsCase(_Float64Default, BaseKernelTestCase, unittest.TestCase):
    seed = 0

    def create_kernel_no_ard(self, **kwargs):
        return InverseMultiquadricKernel(0.5, **kwargs)


class TestMatern52InGPyTorchsCase(_Float64Default, BaseKernelTestCase, unittest.TestCase):
    """Issue 53: four of these errored with a batch of kernels (``shape '[]' is invalid for input of size 2``)."""

    seed = 0

    def create_kernel_no_ard(self, **kwargs):
        return Matern52(0.5, **kwargs)
