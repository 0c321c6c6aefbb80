"""Deprecated: :mod:`torch_gpioius.studies.study_aggregate` (named for a study's tables); its names import from here
for one release."""

from ._moved import forward

__getattr__ = forward("sweep_aggregate", "study_aggregate", "a study's tables")
