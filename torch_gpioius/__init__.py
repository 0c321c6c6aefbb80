"""torch_gpioius: visuo-tactile inner-shape estimation with Gaussian process inner-outer implicit surfaces.

Conventions (DESIGN.md): SI units, float64, ``y = 0`` on a surface and ``y = 1`` in free space, prior mean 1,
``mu < 0`` inside; task 0 is the inner (tactile) shape, task 1 the outer (visual) shape.
"""

from __future__ import annotations

from . import checkpoints, datasets, geometry, importers, metrics, offline, planning, sim, surfaces
from .checkpoints import load_checkpoint, save_checkpoint
from .datasets import Dataset, DatasetError, load_dataset, save_dataset
from .exploration import ObservationPolicy, Trace, explore
from .gpiois import GPIOIS, INNER, OUTER, UnidentifiedSimilarityWarning
from .gpis import GPIS
from .inference import DenseExactInference, JitterWarning, NotPositiveDefiniteError
from .kernels import InverseMultiquadricKernel
from .structured import StructuredExactInference
from .settings import exact_arithmetic
from .tolerances import tol

__version__ = "0.1.0"

__all__ = ["GPIOIS", "GPIS", "ObservationPolicy", "Trace", "explore", "planning", "sim", "INNER", "OUTER", "DenseExactInference", "InverseMultiquadricKernel",
           "JitterWarning", "NotPositiveDefiniteError", "UnidentifiedSimilarityWarning", "StructuredExactInference", "exact_arithmetic", "geometry", "metrics", "surfaces", "tol", "__version__",
           "checkpoints", "datasets", "importers", "offline", "Dataset", "DatasetError", "load_dataset", "save_dataset",
           "load_checkpoint", "save_checkpoint"]
