"""Checkpoints: exact round trip, weights_only loading, tampered and foreign files give clear errors."""

import pickle

import numpy as np
import pytest
import torch

import torch_gpioius as tg
from torch_gpioius.io.checkpoints import CheckpointError


def fitted():
    a = np.linspace(0, 2 * np.pi, 24, endpoint=False)
    x = np.r_[np.c_[0.05 * np.cos(a), 0.05 * np.sin(a)], np.c_[0.08 * np.cos(a), 0.08 * np.sin(a)]]
    return tg.GPIOIS(
        x,
        np.zeros(48),
        np.r_[np.zeros(24), np.ones(24)],
        kernel=tg.kernels.InverseMultiquadricKernel(0.12),
        noise=0.004,
    ).fit()


def test_round_trip_predicts_identically(tmp_path):
    m = fitted()
    p = tg.save_checkpoint(m, tmp_path / "m.pt")
    torch.load(p, weights_only=True)         # plain data: loads with weights_only
    m2 = tg.load_checkpoint(p)
    q = torch.tensor([[0.0, 0.0], [0.06, 0.01], [0.2, 0.1]], dtype=torch.float64)
    for task in (0, 1):
        a, b = m.predict(q, task=task), m2.predict(q, task=task)
        # same parameters and data; the factorisation is rebuilt, so equal to rounding
        assert torch.allclose(a[0], b[0], rtol=1e-12, atol=1e-14) and torch.allclose(a[1], b[1], rtol=1e-10, atol=1e-16)
    assert torch.equal(m.task_covariance, m2.task_covariance)
    gpis = tg.GPIS(m.train_inputs[0][:24], torch.zeros(24, dtype=torch.float64))
    g2 = tg.load_checkpoint(tg.save_checkpoint(gpis, tmp_path / "g.pt"))
    assert isinstance(g2, tg.GPIS) and torch.allclose(g2.predict(q)[0], gpis.predict(q)[0], rtol=1e-12)


def test_tampered_values_are_detected(tmp_path):
    p = tg.save_checkpoint(fitted(), tmp_path / "m.pt")
    payload = torch.load(p, weights_only=True)
    payload["tensors"]["train_x"][0, 0] += 1e-3
    torch.save(payload, p)
    with pytest.raises(CheckpointError, match="SHA-256"):
        tg.load_checkpoint(p)


class Evil:
    def __reduce__(self):
        return (print, ("this must never run",))


def test_code_carrying_pickles_and_foreign_files_are_refused(tmp_path, capsys):
    p = tmp_path / "evil.pt"
    torch.save({"format": "torch_gpioius.checkpoint", "x": Evil()}, p)
    with pytest.raises(CheckpointError, match="not a loadable"):
        tg.load_checkpoint(p)
    assert "must never run" not in capsys.readouterr().out
    (tmp_path / "junk.pt").write_bytes(pickle.dumps([1, 2, 3]))
    with pytest.raises(CheckpointError):
        tg.load_checkpoint(tmp_path / "junk.pt")
    torch.save({"weights": torch.zeros(3)}, tmp_path / "other.pt")
    with pytest.raises(CheckpointError, match="'format'"):
        tg.load_checkpoint(tmp_path / "other.pt")
    with pytest.raises(CheckpointError, match="no such file"):
        tg.load_checkpoint(tmp_path / "missing.pt")


def test_other_version_is_refused(tmp_path):
    p = tg.save_checkpoint(fitted(), tmp_path / "m.pt")
    payload = torch.load(p, weights_only=True)
    payload["version"] = 99
    torch.save(payload, p)
    with pytest.raises(CheckpointError, match="version 99 is not supported"):
        tg.load_checkpoint(p)


def _tamper(p, edit):
    """Edit a saved checkpoint and recompute its (unkeyed) hash, as an attacker or a buggy tool could."""
    from torch_gpioius.io.checkpoints import _digest
    payload = torch.load(p, weights_only=True)
    edit(payload)
    payload["sha256"] = _digest(payload["state_dict"], payload["tensors"])
    torch.save(payload, p)


@pytest.mark.parametrize("field, value, match", [("mean_module.raw_constant", float("nan"), "NaN"),
                                                 ("mean_module.raw_constant", -50.0, "prior mean"),
                                                 ("likelihood.noise_covar.raw_noise", float("inf"), "NaN or inf")])
def test_rehashed_invalid_parameters_are_refused(tmp_path, field, value, match):
    p = tg.save_checkpoint(fitted(), tmp_path / "m.pt")
    _tamper(p, lambda pl: pl["state_dict"].__setitem__(field, torch.full_like(pl["state_dict"][field], value)))
    with pytest.raises(CheckpointError, match=match):
        tg.load_checkpoint(p)


def test_zero_length_and_truncated_files(tmp_path):
    (tmp_path / "z.pt").write_bytes(b"")
    with pytest.raises(CheckpointError, match="z.pt"):
        tg.load_checkpoint(tmp_path / "z.pt")
    good = tg.save_checkpoint(fitted(), tmp_path / "m.pt").read_bytes()
    (tmp_path / "t.pt").write_bytes(good[:len(good) // 2])
    with pytest.raises(CheckpointError, match="t.pt"):
        tg.load_checkpoint(tmp_path / "t.pt")


def test_bad_extra_and_failed_writes_keep_the_good_file(tmp_path, monkeypatch):
    m = fitted()
    p = tg.save_checkpoint(m, tmp_path / "m.pt")
    before = p.read_bytes()
    with pytest.raises(CheckpointError, match="extra"):
        tg.save_checkpoint(m, p, extra={"o": object()})
    import torch_gpioius.io.checkpoints as ck

    def full(*a, **k):
        raise RuntimeError("basic_ios::clear: iostream error")
    monkeypatch.setattr(ck.torch, "save", full)
    with pytest.raises(CheckpointError, match="disk full"):
        tg.save_checkpoint(m, p)
    assert p.read_bytes() == before and not list(tmp_path.glob("*.tmp"))


@pytest.mark.parametrize("kernel", [tg.kernels.Matern52(lengthscale=0.08), tg.kernels.InverseMultiquadricKernel(0.13)],
                         ids=["matern52", "imq"])
def test_every_kernel_prints_checkpoints_and_reloads(tmp_path, kernel):
    """Issue 52, item 2: GPIOIS with Matern52 had model.theta None, repr raised TypeError, save_checkpoint raised
    TypeError and load_checkpoint rebuilt with theta alone. Each kernel now prints, saves and reloads itself, and the
    reloaded model predicts what the saved one did."""
    import torch

    rng = np.random.default_rng(7)
    x = rng.uniform(-0.2, 0.2, (40, 2))
    task = np.r_[np.zeros(20), np.ones(20)].astype(np.int64)
    y = (np.linalg.norm(x, axis=1) > 0.12).astype(float)
    model = tg.GPIOIS(x, y, task, kernel=kernel, noise=0.01).fit()
    text = repr(model)
    assert repr(kernel) in text and "GPIOIS(n_inner=20" in text
    assert model.theta == model.lengthscale == kernel.length
    path = tg.save_checkpoint(model, tmp_path / "m.pt")
    again = tg.load_checkpoint(path)
    assert type(again.kernel) is type(kernel) and again.kernel.describe() == kernel.describe()
    q = torch.as_tensor(rng.uniform(-0.25, 0.25, (50, 2)))
    for task_id in (0, 1):
        m0, v0 = model.predict(q, task_id)
        m1, v1 = again.predict(q, task_id)
        torch.testing.assert_close(m1, m0, rtol=0, atol=1e-10)
        torch.testing.assert_close(v1, v0, rtol=0, atol=1e-10)
