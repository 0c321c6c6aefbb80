"""Deprecated: this module is :mod:`torch_gpioius.studies.study_aggregate` now (named for a study's tables); its names
still import from here for one release, with a DeprecationWarning."""

import importlib
import warnings

warnings.warn(
    "torch_gpioius.studies.sweep_aggregate is torch_gpioius.studies.study_aggregate now (named for a study's tables)",
    DeprecationWarning, stacklevel=2)


def __getattr__(name):
    return getattr(importlib.import_module("torch_gpioius.studies.study_aggregate"), name)
