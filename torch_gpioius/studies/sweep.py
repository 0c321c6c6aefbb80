"""Deprecated: :mod:`torch_gpioius.studies.study` (named for gpioius study); its names import from here for one
release."""

from ._moved import forward

__getattr__ = forward("sweep", "study", "gpioius study")
