"""Deprecated: :mod:`torch_gpioius.studies.simulate` (named for gpioius simulate); its names import from here for one
release."""

from ._moved import forward

__getattr__ = forward("study2d", "simulate", "gpioius simulate")
