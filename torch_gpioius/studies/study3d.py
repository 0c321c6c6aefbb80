"""Deprecated: :mod:`torch_gpioius.studies.simulate3d` (named for gpioius simulate3d); its names import from here for
one release."""

from ._moved import forward

__getattr__ = forward("study3d", "simulate3d", "gpioius simulate3d")
