"""Deprecated: this module is :mod:`torch_gpioius.studies.simulate` now (named for gpioius simulate); its names still
import from here for one release, with a DeprecationWarning."""

import importlib
import warnings

warnings.warn(
    "torch_gpioius.studies.study2d is torch_gpioius.studies.simulate now (named for gpioius simulate)",
    DeprecationWarning, stacklevel=2)


def __getattr__(name):
    return getattr(importlib.import_module("torch_gpioius.studies.simulate"), name)
