"""Differential geometry of the estimated implicit surface by autograd, eq. (20)-(22)."""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import Tensor

from ..core.tolerances import tol

__all__ = ["SurfaceGeometry", "surface_geometry", "predict_task"]


def _per_task(model, method: str, x: Tensor, task: int):
    """``model.<method>(x, task=task)``, or ``model.<method>(x)`` for a single-task model (task 0 only)."""
    if getattr(model, "num_tasks", 1) == 1:
        if task != 0:
            raise ValueError(f"task: a single-task model only has task 0, got {task}")
        return getattr(model, method)(x)
    return getattr(model, method)(x, task=task)


def predict_task(model, x: Tensor, task: int = 0) -> tuple[Tensor, Tensor]:
    """``model.predict`` for either model type: GPIS ignores ``task`` (it has one), GPIOIS takes it."""
    return _per_task(model, "predict", x, task)


def predict_mean_task(model, x: Tensor, task: int = 0) -> Tensor:
    """``model.predict_mean`` for either model type (the mean of :func:`predict_task` without the variance)."""
    return _per_task(model, "predict_mean", x, task)


@dataclass
class SurfaceGeometry:
    """Posterior and first-order geometry of the estimated shape {mu = 0} at query points.

    Attributes:
        mean: `(m,)` posterior mean mu(x).
        var: `(m,)` posterior variance V(x).
        grad_mean: `(m, d)` g_mu = d mu / dx, eq. (20) [1/m].
        grad_var: `(m, d)` dV / dx [1/m].
        normal: `(m, d)` unit normal n = g_mu / |g_mu|, eq. (21), pointing outward (towards increasing mu,
            i.e. into free space); zero where the normal is undefined.
        projector: `(m, d, d)` tangent-plane projector P = I - n n^T, eq. (22); the identity where the normal
            is undefined (no tangency constraint can be formed there).
        normal_defined: `(m,)` bool, |g_mu| > ``tol.normal_eps``.
    """

    mean: Tensor
    var: Tensor
    grad_mean: Tensor
    grad_var: Tensor
    normal: Tensor
    projector: Tensor
    normal_defined: Tensor


def surface_geometry(model, x, task: int = 0) -> SurfaceGeometry:
    """Posterior mean, variance, their gradients, normals and tangent projectors at `(m, d)` points (batched).

    Gradients come from autograd through the exact posterior (each point's prediction depends only on that
    point, so one backward pass of the sum gives every per-point gradient), or, for a GPIOIS on the structured
    engine, from its closed form (``StructuredExactInference.predict_with_gradients``, the same derivatives
    written out; tests hold the two equal).

    Args:
        model: a fitted ``GPIS`` or ``GPIOIS``.
        x: `(m, d)` query points [m], base frame.
        task: 0 (inner) or 1 (outer); GPIS has only 0.

    Returns:
        ``SurfaceGeometry`` with all fields detached.
    """
    x0 = model.train_inputs[0]
    xq = torch.as_tensor(x, dtype=x0.dtype, device=x0.device).detach().clone()
    closed_form = getattr(model, "_predict_with_gradients", None)
    result = closed_form(xq, task) if closed_form is not None and getattr(model, "num_tasks", 1) > 1 else None
    if result is not None:   # the structured engine's closed form: one pass over its rotation instead of three
        mean, var, grad_mean, grad_var = result
    else:
        xq.requires_grad_(True)
        with torch.enable_grad():
            mean, var = predict_task(model, xq, task)
            grad_mean, = torch.autograd.grad(mean.sum(), xq, retain_graph=True)
            grad_var, = torch.autograd.grad(var.sum(), xq)
    norm = grad_mean.norm(dim=-1, keepdim=True)
    defined = norm.squeeze(-1) > tol.normal_eps
    normal = torch.where(defined.unsqueeze(-1), grad_mean / norm.clamp_min(tol.normal_eps),
                         torch.zeros_like(grad_mean))
    eye = torch.eye(xq.shape[-1], dtype=xq.dtype, device=xq.device)
    projector = eye - normal.unsqueeze(-1) * normal.unsqueeze(-2)
    return SurfaceGeometry(mean.detach(), var.detach(), grad_mean.detach(), grad_var.detach(), normal.detach(),
                           projector.detach(), defined)
