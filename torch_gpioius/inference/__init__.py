"""Exact GP arithmetic behind the models: the dense Cholesky reference, the structured engine for a fixed outer
set, and the second-order K_t optimiser (eq. 15-16)."""

from .dense import DenseExactInference, JitterWarning, NotPositiveDefiniteError, bordered, robust_cholesky
from .optim import FitResult, maximize_mll
from .structured import StructuredExactInference
from .batched import BatchedExactInference

__all__ = ["DenseExactInference", "StructuredExactInference", "BatchedExactInference", "JitterWarning",
           "NotPositiveDefiniteError", "robust_cholesky", "bordered", "FitResult", "maximize_mll"]
