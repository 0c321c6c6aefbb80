"""Deprecated: this module is :mod:`torch_gpioius.exact` now ("settings" are the estimator's,
:mod:`torch_gpioius.models.estimator`); ``tg.exact_arithmetic`` is unchanged."""

import warnings

from .exact import exact_arithmetic  # noqa: F401

__all__ = ["exact_arithmetic"]

warnings.warn("torch_gpioius.settings is torch_gpioius.exact now (settings are the estimator's)", DeprecationWarning,
              stacklevel=2)
