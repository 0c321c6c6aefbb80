"""Deprecated: :mod:`torch_gpioius.studies.study_runs` (named for a study's runs); its names import from here for one
release."""

from ._moved import forward

__getattr__ = forward("sweep_runs", "study_runs", "a study's runs")
