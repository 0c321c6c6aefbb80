"""torch_gpioius: visuo-tactile inner-shape estimation with Gaussian process inner-outer implicit surfaces.

Conventions (docs/theory.md, "Conventions"): SI units, float64, ``y = 0`` on a surface and ``y = 1`` in free space,
prior mean 1, ``mu < 0`` inside; task 0 is the inner (tactile) shape, task 1 the outer (visual) shape; boxes are ``(2,
d)`` [min corner; max corner].

Layers, each importing only those before it (docs/architecture.md): ``core`` (tolerances, exact arithmetic, threads,
registries, validation) -> ``geometry`` (voxels, curves, the estimated surface's geometry, extraction and metrics) ->
``kernels`` -> ``inference`` (exact engines, the K_t fit) -> ``models`` (GPIS, GPIOIS, LocalGPIOIS) -> ``sensors``
(real and simulated) -> ``exploration`` (public types, contracts, the planner, the contact controller, one loop, the
world registry) -> ``sim`` (the worlds) -> ``baselines`` -> ``io`` (datasets, logs and resume, checkpoints, importers,
exports) -> ``session`` (``tg.explore``: the loop with its log), ``fitting`` -> ``studies``, ``viewer``, ``cli``.
Modules of earlier releases import from their old paths for one release (:mod:`torch_gpioius.core.moved`).
"""

from __future__ import annotations

import sys as _sys

from ._version import __version__  # noqa: E402
from .core import moved as _moved  # noqa: E402

_moved.install()

from . import geometry, kernels, sim  # noqa: E402
from .geometry import metrics, surfaces  # noqa: E402
from .exploration import planning  # noqa: E402
from . import exploration, inference, io, models  # noqa: E402
from .exploration import ObservationPolicy, Observations, RobotWorld, Trace, World  # noqa: E402
from .session import explore  # noqa: E402
from .inference import (DenseExactInference, JitterWarning, NotPositiveDefiniteError,  # noqa: E402
                        StructuredExactInference)
from .io import (BagImportError, CheckpointError, Dataset, DatasetError, RunHistory, checkpoints,  # noqa: E402
                 datasets, export_run, import_bag, importers, load_checkpoint, load_dataset, load_run,
                 save_checkpoint, save_dataset)
from .kernels import InverseMultiquadricKernel  # noqa: E402
from .models import GPIOIS, GPIS, INNER, OUTER, LocalGPIOIS, UnidentifiedSimilarityWarning  # noqa: E402
from .models.estimator import EstimatorSettings  # noqa: E402
from .models.overrides import EstimatorOverrides  # noqa: E402
from .core.exact import exact_arithmetic  # noqa: E402
from .core.threads import torch_threads  # noqa: E402
from .core.tolerances import tol  # noqa: E402

__all__ = ["GPIOIS", "GPIS", "LocalGPIOIS", "INNER", "OUTER", "EstimatorSettings", "EstimatorOverrides",
           "InverseMultiquadricKernel",
           "DenseExactInference", "StructuredExactInference", "JitterWarning", "NotPositiveDefiniteError",
           "UnidentifiedSimilarityWarning", "exact_arithmetic", "tol", "torch_threads", "__version__",
           "ObservationPolicy", "Trace", "World", "RobotWorld", "Observations", "explore", "kernels", "models",
           "inference", "exploration", "io", "geometry", "metrics", "planning", "surfaces", "sim", "checkpoints",
           "datasets", "importers", "offline", "fitting", "Dataset", "DatasetError", "CheckpointError", "load_dataset",
           "save_dataset", "load_checkpoint", "save_checkpoint", "import_bag", "BagImportError", "export_run",
           "load_run", "RunHistory"]

from . import fitting  # noqa: E402

offline = fitting               # 0.1's torch_gpioius.offline: fitting and replay, now their own room

# the io modules of 0.1 are also attributes of the package (tg.datasets, ...): their module paths stay the real ones
for _old in ("datasets", "checkpoints", "importers"):
    _sys.modules.setdefault(f"{__name__}.{_old}", getattr(io, _old))
_sys.modules.setdefault(f"{__name__}.offline", fitting)
del _old
