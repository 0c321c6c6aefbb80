"""The GP models: GPIS (one shape, the tactile-only baseline) and GPIOIS (inner and outer shapes, one GP).

Both are ``gpytorch.models.ExactGP`` subclasses whose arithmetic runs in the exact engines of
:mod:`torch_gpioius.inference`.
"""

from .base import ImplicitSurfaceGP
from .gpiois import GPIOIS, INNER, OUTER, UnidentifiedSimilarityWarning
from .gpis import GPIS

__all__ = ["ImplicitSurfaceGP", "GPIS", "GPIOIS", "INNER", "OUTER", "UnidentifiedSimilarityWarning"]
