"""torch_gpioius: visuo-tactile inner-shape estimation with Gaussian process inner-outer implicit surfaces.

Conventions (DESIGN.md): SI units, float64, ``y = 0`` on a surface and ``y = 1`` in free space, prior mean 1,
``mu < 0`` inside; task 0 is the inner (tactile) shape, task 1 the outer (visual) shape; boxes are ``(2, d)``
[min corner; max corner].

Layout (the data flow): ``kernels`` -> ``models`` (GPIS, GPIOIS) -> ``inference`` (exact engines, the K_t fit)
-> ``geometry`` / ``surfaces`` / ``metrics`` -> ``planning`` -> ``exploration`` (one loop, behind the robot,
force-sensor and point-cloud interfaces) <- ``sim`` (the worlds) and ``sensors``; ``io`` (datasets, logs,
checkpoints, importers), ``studies``, ``cli``.
"""

from __future__ import annotations

import sys as _sys
from importlib import import_module as _import_module

__version__ = "0.2.0"

from . import geometry, metrics, planning, sim, surfaces  # noqa: E402
from . import exploration, inference, io, models  # noqa: E402
from .exploration import ObservationPolicy, RobotWorld, Trace, World, explore  # noqa: E402
from .inference import (DenseExactInference, JitterWarning, NotPositiveDefiniteError,  # noqa: E402
                        StructuredExactInference)
from .io import (BagImportError, CheckpointError, Dataset, DatasetError, RunHistory, checkpoints,  # noqa: E402
                 datasets, export_run, import_bag, importers, load_checkpoint, load_dataset, load_run, offline,
                 save_checkpoint, save_dataset)
from .kernels import InverseMultiquadricKernel  # noqa: E402
from .models import GPIOIS, GPIS, INNER, OUTER, LocalGPIOIS, UnidentifiedSimilarityWarning  # noqa: E402
from .settings import exact_arithmetic  # noqa: E402
from .threads import torch_threads  # noqa: E402
from .tolerances import tol  # noqa: E402

__all__ = ["GPIOIS", "GPIS", "LocalGPIOIS", "INNER", "OUTER", "InverseMultiquadricKernel", "DenseExactInference",
           "StructuredExactInference", "JitterWarning", "NotPositiveDefiniteError", "UnidentifiedSimilarityWarning",
           "exact_arithmetic", "tol", "torch_threads", "__version__", "ObservationPolicy", "Trace", "World",
           "RobotWorld", "explore", "models", "inference", "exploration", "io", "geometry", "metrics", "planning",
           "surfaces", "sim", "checkpoints", "datasets", "importers", "offline", "Dataset", "DatasetError",
           "CheckpointError", "load_dataset", "save_dataset", "load_checkpoint", "save_checkpoint", "import_bag",
           "BagImportError", "export_run", "load_run", "RunHistory"]

# Module paths of the 0.1 layout keep working (``from torch_gpioius.gpiois import GPIOIS``, ...): each old name
# points at the module that holds the code now.
for _old, _new in {"gpiois": models.gpiois, "gpis": models.gpis, "_base": models.base,
                   "structured": inference.structured, "optim": inference.optim, "datasets": io.datasets,
                   "checkpoints": io.checkpoints, "importers": io.importers, "offline": io.offline,
                   "study": _import_module(f"{__name__}.studies.study2d"),
                   "study3d": _import_module(f"{__name__}.studies.study3d")}.items():
    _sys.modules.setdefault(f"{__name__}.{_old}", _new)
del _old, _new, _import_module
