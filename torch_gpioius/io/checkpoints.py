"""Save and load fitted models: ``state_dict`` plus the data it needs, loaded with ``weights_only=True``."""

from __future__ import annotations

import hashlib
import os
import secrets
from pathlib import Path

import torch

__all__ = ["CheckpointError", "save_checkpoint", "load_checkpoint", "CHECKPOINT_VERSION"]

CHECKPOINT_VERSION = 1
_FORMAT = "torch_gpioius.checkpoint"


class CheckpointError(ValueError):
    """A checkpoint file is unreadable, from another format version, or was modified after saving."""


def _digest(state: dict, tensors: dict) -> str:
    h = hashlib.sha256()
    for name in sorted(state):
        h.update(name.encode())
        h.update(state[name].detach().cpu().contiguous().numpy().tobytes())
    for name in sorted(tensors):
        h.update(name.encode())
        h.update(tensors[name].detach().cpu().contiguous().numpy().tobytes())
    return h.hexdigest()


def _check_extra(extra, where: str = "extra"):
    """``extra`` must be plain JSON-like data (what ``weights_only`` loading accepts): strings, numbers, bools,
    None, and lists / dicts with string keys of those."""
    if extra is None or isinstance(extra, (str, bool, int, float)):
        return
    if isinstance(extra, (list, tuple)):
        for i, v in enumerate(extra):
            _check_extra(v, f"{where}[{i}]")
        return
    if isinstance(extra, dict):
        for k, v in extra.items():
            if not isinstance(k, str):
                raise CheckpointError(f"{where}: keys must be strings, got {k!r}")
            _check_extra(v, f"{where}[{k!r}]")
        return
    raise CheckpointError(f"{where}: only strings, numbers, bools, None, lists and dicts can be stored (a "
                          f"checkpoint loads with weights_only=True), got {type(extra).__name__}")


def save_checkpoint(model, path: str | os.PathLike, *, extra: dict | None = None) -> Path:
    """Write a fitted :class:`~torch_gpioius.GPIOIS` or :class:`~torch_gpioius.GPIS` to ``path``.

    The file holds only tensors, numbers and strings (so it loads with ``torch.load(weights_only=True)``),
    a SHA-256 over them, and the format version. Written atomically: everything is validated first (the model's
    state as the constructor would, ``extra`` as plain data), then written to a temporary file that is renamed
    over ``path``; a failed write (disk full) removes the temporary file and leaves a previous file untouched.

    The SHA-256 is unkeyed: it detects accidental damage (a truncated copy, a flipped bit, a file edited by
    hand), not a deliberate forgery, which could simply recompute it. ``load_checkpoint`` never runs code
    from the file (``weights_only=True``) and validates every loaded parameter, whatever the hash says.

    Args:
        model: the model.
        path: destination (conventionally ``.pt``).
        extra: small JSON-like metadata to keep alongside (strings, numbers, lists, dicts).

    Raises:
        CheckpointError: invalid model state or ``extra``, or the write failed (names the cause).
    """
    from .._version import __version__
    from ..models.gpiois import GPIOIS
    from ..models.gpis import GPIS

    if not isinstance(model, (GPIOIS, GPIS)):
        raise CheckpointError(f"save_checkpoint: expected a GPIOIS or GPIS, got {type(model).__name__}")
    _check_extra(extra)
    try:
        model.check_state()
    except ValueError as exc:
        raise CheckpointError(f"save_checkpoint: the model's state is invalid ({exc}); nothing was written") from exc
    kind = "GPIOIS" if isinstance(model, GPIOIS) else "GPIS"
    state = {k: v.detach().cpu().clone() for k, v in model.state_dict().items()}
    tensors = {"train_x": model.train_inputs[0].detach().cpu().clone(),
               "train_y": model.train_targets.detach().cpu().clone()}
    if kind == "GPIOIS":
        tensors["train_task"] = model.train_inputs[1].detach().cpu().reshape(-1).clone()
        field = model.outer_field
        if field is not None:      # the outer mean's gap field: its gaps, where they were measured, its numbers
            tensors["outer_field_points"] = field.points.clone()
            tensors["outer_field_gaps"] = field.gaps.clone()
            params = [field.length, field.scale, field.noise, field.prior, field.ramp] + (
                [field.carry] if field.carry else [])                  # the carry since 2026-12-01, when not 0
            tensors["outer_field_params"] = torch.tensor(params, dtype=torch.float64)
    kernel = model.kernel.describe()
    _check_extra(kernel, "the kernel's description")
    payload = {
        "format": _FORMAT, "version": CHECKPOINT_VERSION, "library_version": __version__, "kind": kind,
        "kernel": kernel, "noise": float(model.noise),
        "inference": getattr(model, "inference", "dense"), "state_dict": state, "tensors": tensors,
        "sha256": _digest(state, tensors), "extra": dict(extra or {}),
    }
    path = Path(path)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.{secrets.token_hex(4)}.tmp")   # unique to this writer
    try:
        torch.save(payload, tmp)
        with open(tmp, "rb+") as f:
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except (OSError, RuntimeError) as exc:   # torch reports a full disk as RuntimeError("basic_ios::clear")
        try:
            tmp.unlink()
        except OSError:
            pass
        raise CheckpointError(f"{path}: could not write the checkpoint ({type(exc).__name__}: {exc}; disk full or "
                              "not writable?); a previous file there is unchanged") from exc
    return path


def load_checkpoint(path: str | os.PathLike):
    """Load a model saved by :func:`save_checkpoint` (``weights_only=True``: no code runs while loading).

    Returns:
        The model in eval mode, with the saved K_t, theta and noise.

    Raises:
        CheckpointError: not a checkpoint, a pickle that is not plain data (tampered), another format
            version, or contents that no longer match their SHA-256.
    """
    from ..models.gpiois import GPIOIS
    from ..models.gpis import GPIS

    path = Path(path)
    try:
        payload = torch.load(path, map_location="cpu", weights_only=True)
    except FileNotFoundError:
        raise CheckpointError(f"{path}: no such file") from None
    except Exception as exc:  # UnpicklingError for code-carrying pickles, RuntimeError for non-zip files, ...
        first = (str(exc).splitlines() or [""])[0][:200]
        raise CheckpointError(f"{path}: not a loadable torch_gpioius checkpoint ({type(exc).__name__}: "
                              f"{first or 'empty or truncated file'})") from exc
    if not isinstance(payload, dict) or payload.get("format") != _FORMAT:
        raise CheckpointError(f"{path}: not a torch_gpioius checkpoint (field 'format' missing or wrong)")
    if payload.get("version") != CHECKPOINT_VERSION:
        raise CheckpointError(f"{path}: checkpoint version {payload.get('version')!r} is not supported (this "
                              f"torch_gpioius reads version {CHECKPOINT_VERSION}; saved by "
                              f"{payload.get('library_version')!r})")
    try:
        state, tensors = payload["state_dict"], payload["tensors"]
        ok = payload["sha256"] == _digest(state, tensors)
    except (KeyError, AttributeError, TypeError) as exc:
        raise CheckpointError(f"{path}: checkpoint is missing field {exc}") from exc
    if not ok:
        raise CheckpointError(f"{path}: contents do not match the stored SHA-256 (the file was modified)")
    try:
        if not isinstance(payload.get("noise"), float):
            raise CheckpointError(f"{path}: field 'noise' must be a number")
        kernel = _kernel(payload, path)
        if payload["kind"] == "GPIOIS":
            model = GPIOIS(tensors["train_x"], tensors["train_y"], tensors["train_task"], kernel=kernel,
                           noise=payload["noise"], inference=payload["inference"])
        elif payload["kind"] == "GPIS":
            model = GPIS(tensors["train_x"], tensors["train_y"], kernel=kernel, noise=payload["noise"])
        else:
            raise CheckpointError(f"{path}: unknown model kind {payload['kind']!r}")
        if payload["kind"] == "GPIOIS" and "outer_mean_module.raw_constant" not in state:
            # saved before the outer task had a prior mean of its own (2026-11-27): the paper's, 1, for both tasks
            state = {**state, "outer_mean_module.raw_constant": torch.ones((), dtype=torch.float64)}
        model.load_state_dict(state)
        if "outer_field_points" in tensors:        # saved with the outer mean a gap field (since 2026-11-29)
            from ..models.gapfield import GapField

            params = tensors["outer_field_params"].tolist()
            if len(params) not in (5, 6):
                raise ValueError(f"outer_field_params: 5 or 6 numbers, got {len(params)}")
            model.set_outer_mean(GapField(tensors["outer_field_points"], tensors["outer_field_gaps"], *params))
    except (KeyError, ValueError, RuntimeError) as exc:
        raise CheckpointError(f"{path}: checkpoint data is inconsistent ({exc})") from exc
    model.eval()
    return model


def _kernel(payload: dict, path: Path):
    """The kernel a checkpoint names (its description), or the inverse multiquadric of its ``theta`` (checkpoints
    written before the kernel carried its description)."""
    from ..kernels import kernel_of_record

    if "kernel" in payload and not isinstance(payload["kernel"], dict):
        raise CheckpointError(f"{path}: field 'kernel' must be a kernel's description")
    if "kernel" not in payload and not isinstance(payload.get("theta"), float):
        raise CheckpointError(f"{path}: fields 'kernel' (or 'theta') must describe the kernel")
    return kernel_of_record(payload)
