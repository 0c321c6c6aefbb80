"""Deprecated: :mod:`torch_gpioius.studies.study_plan` (named for a study's plan); its names import from here for one
release."""

from ._moved import forward

__getattr__ = forward("sweep_settings", "study_plan", "a study's plan")
