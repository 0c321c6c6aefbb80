"""Deprecated: :mod:`torch_gpioius.studies.study_figures` (named for a study's figures); its names import from here for
one release."""

from ._moved import forward

__getattr__ = forward("sweep_figures", "study_figures", "a study's figures")
