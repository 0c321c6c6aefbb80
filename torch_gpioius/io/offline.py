"""Deprecated: :mod:`torch_gpioius.fitting` (the ``fit`` and ``replay`` commands' work: it fits and plots, this package
holds the file formats); its names import from here for one release."""

import importlib
import warnings

warnings.warn("torch_gpioius.io.offline is torch_gpioius.fitting now (fitting and plotting apart from the file "
              "formats)", DeprecationWarning, stacklevel=2)


def __getattr__(name):
    return getattr(importlib.import_module("torch_gpioius.fitting"), name)
