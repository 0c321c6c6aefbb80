"""The studies' modules of earlier releases, forwarded to where they live now, named for the commands they serve."""

import importlib
import warnings


def forward(old: str, new: str, job: str):
    """Warn that ``torch_gpioius.studies.<old>`` is ``<new>`` now (named for ``job``) and return the module
    ``__getattr__`` that gives the new module's names from the old one, for one release."""
    warnings.warn(f"torch_gpioius.studies.{old} is torch_gpioius.studies.{new} now (named for {job})",
                  DeprecationWarning, stacklevel=3)

    def __getattr__(name):
        return getattr(importlib.import_module(f"torch_gpioius.studies.{new}"), name)

    return __getattr__
