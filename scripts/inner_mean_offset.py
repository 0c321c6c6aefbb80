"""Would a constant prior mean of its own for the inner task remove the estimate's offset? On finished runs' data.

The paper's prior mean is m = 1 for both tasks. Away from the touches the inner mean follows the outer field through
K_t (docs/method-notes.md sections 5 and 13), so a cover that stands off the body by a near-constant gap could be
absorbed by an inner-task mean ``1 + delta``: the touches would calibrate the offset everywhere. For a fixed K_t the
marginal likelihood's best ``delta`` has a closed form, the generalised-least-squares mean
``delta = e0^T G^-1 (y - 1) / e0^T G^-1 e0`` (``e0``: 1 on the inner task's rows, ``G`` the Gram matrix with the
noise). A mean of ``1 + delta`` on the inner task is the model on labels ``y - delta`` (inner rows) with ``delta``
added to the inner task's prediction, which is how it is evaluated here (the library's labels are 0, 1 or negative:
the shifted labels are set on the model directly).

For each log: the run's final data with its logged K_t (``base``); with ``delta`` at that K_t (``gls``); and with
``delta`` and K_t alternated three times (K_t re-fitted on the shifted labels, ``delta`` again at the new K_t;
``alt``). Each is measured as the studies measure (``Scene3D.measure``: Hausdorff, Chamfer, F-score at 1 cm, bias).
docs/method-notes.md section 13 reports what it printed.

    python scripts/inner_mean_offset.py outputs/real_ff_wide/logs/duck-wide_visual-tactile_0.gpioius ...

The logs must come from a study of ``examples/scenes/real/*.toml`` (each log's name gives its scene and seed).
"""

from __future__ import annotations

import sys
import types
import warnings

import torch

import torch_gpioius as tg
from torch_gpioius.io.runs import load_run
from torch_gpioius.sim.scenefile import load_scene


def _gram(model) -> torch.Tensor:
    x, t = model.train_inputs[0], model.train_task
    return (model.covar_module.value(x, x) * model.task_covariance[t][:, t]
            + model.noise * torch.eye(len(x), dtype=x.dtype))


def gls_offset(model) -> float:
    """The marginal likelihood's inner-task mean offset at the model's K_t (closed form)."""
    chol = torch.linalg.cholesky(_gram(model))
    e0 = (model.train_task == 0).double().unsqueeze(-1)
    a = torch.cholesky_solve(e0, chol)
    return float((a.T @ (model.train_targets - 1.0).unsqueeze(-1)) / (a.T @ e0))


def with_offset(model, delta: float, refit: bool = False):
    """The model with an inner-task prior mean of ``1 + delta`` (K_t as given, or re-fitted with ``refit``)."""
    x, y, t = model.train_inputs[0], model.train_targets, model.train_task
    shifted = tg.GPIOIS(x, y, t, noise=model.noise, kernel=model.covar_module, task_covariance=model.task_covariance)
    shifted.train_targets = y - delta * (t == 0).double()
    shifted._engine = None
    if refit:
        shifted.fit()
    predict, predict_mean = shifted._predict, shifted._predict_mean

    def _predict(self, xq, task):
        mu, var = predict(xq, task)
        return (mu + delta if task == 0 else mu), var

    def _predict_mean(self, xq, task):
        mu = predict_mean(xq, task)
        return mu + delta if task == 0 else mu

    shifted._predict = types.MethodType(_predict, shifted)
    shifted._predict_mean = types.MethodType(_predict_mean, shifted)
    return shifted


def _row(tag: str, scene, model, contacts) -> str:
    m = scene.measure(model, contacts)
    sh = m.shape
    return (f"{tag}: H {m.hausdorff * 100:.1f} Ch {sh['chamfer'] * 100:.2f} F1 {sh['fscore_10mm']:.2f} "
            f"bias {sh['bias'] * 100:+.2f} rho {model.correlation:.2f}")


def final_state(path):
    """A real-shape study log's ``(run, scene, model, data, contacts)`` at its last step: the scene rebuilt from
    ``examples/scenes/real`` with the log's seed (its name gives both), the model and data of that step, and the
    contacts (inner task, y = 0) `(k, 3)` [m]. scripts/camera_inside_depths.py reads its logs with it too."""
    run = load_run(path)
    name, _, seed = run.path.stem.rsplit("_", 2)
    scene = load_scene(f"examples/scenes/real/{name}.toml", seed=int(seed))
    last = run.steps[-1]
    model, data = run.model_at(last), run.states[last]
    return run, scene, model, data, data.x[(data.task == 0) & (data.y == 0)]


def main(paths: list[str]) -> None:
    warnings.simplefilter("ignore")
    torch.set_num_threads(1)
    for path in paths:
        run, scene, model, data, contacts = final_state(path)
        out = [_row("base", scene, model, contacts)]
        delta = gls_offset(model)
        out.append(_row(f"gls d={delta:+.3f}", scene, with_offset(model, delta), contacts))
        for _ in range(3):
            refit = with_offset(model, delta, refit=True)
            at = tg.GPIOIS(model.train_inputs[0], model.train_targets, model.train_task, noise=model.noise,
                           kernel=model.covar_module, task_covariance=refit.task_covariance)
            delta = gls_offset(at)
        out.append(_row(f"alt d={delta:+.3f}", scene, with_offset(model, delta, refit=True), contacts))
        print(run.path.stem, " | ".join(out), flush=True)


if __name__ == "__main__":
    main(sys.argv[1:])
