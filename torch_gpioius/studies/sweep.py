"""Deprecated: this module is :mod:`torch_gpioius.studies.study` now (named for gpioius study); its names still import
from here for one release, with a DeprecationWarning."""

import importlib
import warnings

warnings.warn(
    "torch_gpioius.studies.sweep is torch_gpioius.studies.study now (named for gpioius study)",
    DeprecationWarning, stacklevel=2)


def __getattr__(name):
    return getattr(importlib.import_module("torch_gpioius.studies.study"), name)
