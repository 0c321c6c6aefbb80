"""The GP models: GPIS (one shape, the tactile-only baseline) and GPIOIS (inner and outer shapes, one GP), and the
estimator's settings that make them from observations (:class:`EstimatorSettings`, its labelling policy
:class:`ObservationPolicy`).

Both are ``gpytorch.models.ExactGP`` subclasses whose arithmetic runs in the exact engines of
:mod:`torch_gpioius.inference`.
"""

from .base import ImplicitSurfaceGP
from .estimator import EstimatorSettings, LengthRule, VoxelRule
from .gpiois import GPIOIS, INNER, OUTER, UnidentifiedSimilarityWarning
from .labels import ObservationPolicy
from .gpis import GPIS
from .local import LocalGPIOIS, kmeans_regions

__all__ = ["ImplicitSurfaceGP", "GPIS", "GPIOIS", "LocalGPIOIS", "kmeans_regions", "INNER", "OUTER",
           "UnidentifiedSimilarityWarning", "EstimatorSettings", "LengthRule", "VoxelRule", "ObservationPolicy"]
