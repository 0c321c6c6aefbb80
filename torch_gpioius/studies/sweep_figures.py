"""Deprecated: this module is :mod:`torch_gpioius.studies.study_figures` now (named for a study's figures); its names
still import from here for one release, with a DeprecationWarning."""

import importlib
import warnings

warnings.warn(
    "torch_gpioius.studies.sweep_figures is torch_gpioius.studies.study_figures now (named for a study's figures)",
    DeprecationWarning, stacklevel=2)


def __getattr__(name):
    return getattr(importlib.import_module("torch_gpioius.studies.study_figures"), name)
