"""GPyTorch settings that keep every solve and log-determinant on the exact Cholesky path."""

from __future__ import annotations

import warnings
from contextlib import ExitStack, contextmanager
from typing import Iterator

import gpytorch

__all__ = ["exact_arithmetic"]

#: Larger than any Gram matrix that fits in memory: GPyTorch never switches to CG/Lanczos below it.
_NEVER = 2**40


@contextmanager
def exact_arithmetic() -> Iterator[None]:
    """Context in which GPyTorch uses Cholesky for every solve, log-determinant and predictive variance.

    GPyTorch silently switches to conjugate gradients and stochastic Lanczos quadrature above
    ``max_cholesky_size`` (800 by default); results then differ by ~1e-3 and variance gradients become noise
    (docs/theory.md, "Why exact arithmetic"). The models of this library enter this context in ``__call__``, but
    linear_operator's autograd functions read the settings again during ``backward``: run the backward pass inside the
    context as well, or gradients above N = 800 silently come from CG (measured: up to 2x off). ``model.predict`` has no
    such caveat. Wrap your own GPyTorch training loops like this::

        with tg.exact_arithmetic():
            loss = -mll(model(*model.train_inputs), model.train_targets)
            loss.backward()
    """
    with ExitStack() as stack:
        stack.enter_context(gpytorch.settings.max_cholesky_size(_NEVER))
        stack.enter_context(gpytorch.settings.fast_computations(covar_root_decomposition=False, log_prob=False,
                                                                solves=False))
        stack.enter_context(gpytorch.settings.fast_pred_var(False))
        stack.enter_context(gpytorch.settings.skip_posterior_variances(False))
        # linear_operator builds a sparse COO summing matrix for IndexKernel; torch then warns, once per
        # process, that it does not check sparse invariants. The indices are linear_operator's own: not news for
        # the user of ``model(x, task)``.
        stack.enter_context(warnings.catch_warnings())
        warnings.filterwarnings("ignore", message="Sparse invariant checks are implicitly disabled",
                                category=UserWarning)
        yield
