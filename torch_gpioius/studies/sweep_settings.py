"""Deprecated: this module is :mod:`torch_gpioius.studies.study_plan` now (named for a study's plan); its names still
import from here for one release, with a DeprecationWarning."""

import importlib
import warnings

warnings.warn(
    "torch_gpioius.studies.sweep_settings is torch_gpioius.studies.study_plan now (named for a study's plan)",
    DeprecationWarning, stacklevel=2)


def __getattr__(name):
    return getattr(importlib.import_module("torch_gpioius.studies.study_plan"), name)
