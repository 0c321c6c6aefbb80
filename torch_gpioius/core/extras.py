"""How to install an optional extra, said the same way by every message that needs one."""

from __future__ import annotations

__all__ = ["install_hint"]


def install_hint(extra: str) -> str:
    """The two ways to install the extra ``extra``: from PyPI, and into a checkout as the README installs it."""
    return f"pip install 'torch_gpioius[{extra}]' (in a checkout: pip install -e '.[{extra}]')"
