"""device=: the models run where their data live, float64 throughout; CUDA is checked when a GPU is present."""

import pytest
import torch

import torch_gpioius as tg


def _data():
    g = torch.Generator().manual_seed(0)
    x = torch.rand(60, 3, generator=g, dtype=torch.float64) - 0.5
    y = (x.norm(dim=1) > 0.3).double()
    task = (torch.arange(60) % 3 == 0).long()
    return x, y, task


def test_device_cpu_is_the_default_arithmetic():
    x, y, task = _data()
    q = x[:5] + 0.01
    a = tg.GPIOIS(x, y, task, kernel=tg.kernels.InverseMultiquadricKernel(0.2), noise=0.01).fit()
    b = tg.GPIOIS(x, y, task, kernel=tg.kernels.InverseMultiquadricKernel(0.2), noise=0.01, device="cpu").fit()
    assert torch.equal(a.task_covariance, b.task_covariance)
    assert torch.equal(a.predict(q)[0], b.predict(q)[0])
    c = tg.GPIS(x, y, kernel=tg.kernels.InverseMultiquadricKernel(0.2), device=torch.device("cpu"))
    assert c.train_inputs[0].device.type == "cpu" and c.train_inputs[0].dtype == torch.float64


@pytest.mark.parametrize("bad", ["gpu", "cuda:99" if torch.cuda.is_available() else "cuda"])
def test_an_unusable_device_is_named(bad):
    x, y, task = _data()
    with pytest.raises(ValueError, match="device"):
        tg.GPIOIS(x, y, task, device=bad)


@pytest.mark.skipif(not torch.cuda.is_available(), reason="no CUDA device on this machine (the CPU path is tested)")
def test_cuda_agrees_with_cpu():
    x, y, task = _data()
    q = x[:5] + 0.01
    cpu = tg.GPIOIS(x, y, task, theta=0.2, noise=0.01).fit()
    gpu = tg.GPIOIS(x, y, task, theta=0.2, noise=0.01, device="cuda").fit()
    assert gpu.train_inputs[0].is_cuda
    assert gpu.task_covariance.is_cuda   # K_t lives where the model lives
    assert float((gpu.task_covariance.cpu() - cpu.task_covariance).abs().max()) < 1e-9
    m_c, v_c = cpu.predict(q)
    m_g, v_g = gpu.predict(q.cuda())
    assert float((m_g.cpu() - m_c).abs().max()) < 1e-9 and float((v_g.cpu() - v_c).abs().max()) < 1e-9


@pytest.mark.parametrize("bad", ["meta", "cuda:99" if torch.cuda.is_available() else "cuda"])
def test_devices_that_cannot_compute_are_refused_with_the_available_ones(bad):
    """Issue 33, item 14: `--device meta` failed with "Tensor.item() cannot be called on meta tensors"."""
    from torch_gpioius.core.validation import as_device, available_devices

    with pytest.raises(ValueError, match=r"device: cannot use .* here .*available: cpu"):
        as_device(bad)
    assert available_devices()[0] == "cpu" and all(as_device(d).type in ("cpu", "cuda", "mps")
                                                   for d in available_devices())


def test_the_cli_refuses_the_meta_device(capsys, tmp_path):
    from torch_gpioius.cli import main

    with pytest.raises(SystemExit):
        main(["simulate3d", "--device", "meta", "--out", str(tmp_path / "x")])
    assert "holds no data to compute with" in capsys.readouterr().err
