"""Deprecated home of :func:`torch_gpioius._validation.as_bounds` (an input check belongs with the other checks)."""

from .._validation import as_bounds

__all__ = ["as_bounds"]
