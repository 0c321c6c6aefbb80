"""Deprecated module name of the force-field world: :mod:`torch_gpioius.sim.forcefield` ("penalty" now names only
the planner's range cost C(x) of eq. 25)."""

import warnings

from .forcefield import *  # noqa: F401,F403
from .forcefield import __all__  # noqa: F401

warnings.warn("torch_gpioius.sim.penalty is torch_gpioius.sim.forcefield now", DeprecationWarning, stacklevel=2)
