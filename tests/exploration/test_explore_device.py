"""explore(device=): the model computes on the device, the robot side stays on the CPU; the study and the CLI pass it.
CUDA is checked when a GPU is present (the CPU path always)."""

import numpy as np
import pytest
import torch

import torch_gpioius as tg
from torch_gpioius.cli import main as cli_main
from torch_gpioius.studies.study_runs import RunSpec, _explore_kwargs


def _run(device, mode="visual-tactile", steps=6):
    scene = tg.sim.paper_objects_2d()["A"]
    return tg.explore(scene, mode, max_steps=steps, device=device)


@pytest.mark.parametrize("mode", ["visual-tactile", "tactile"])
def test_device_cpu_is_the_default_run(mode):
    a, b = _run(None, mode), _run("cpu", mode)
    np.testing.assert_array_equal(a.contacts, b.contacts)
    np.testing.assert_array_equal(a.task_covariance, b.task_covariance)
    assert b.model.train_inputs[0].device.type == "cpu"


def test_an_unusable_device_is_refused_before_the_run():
    scene = tg.sim.paper_objects_2d()["A"]
    with pytest.raises(ValueError, match="device"):
        tg.explore(scene, max_steps=1, device="gpu")
    bad = "cuda:99" if torch.cuda.is_available() else "cuda"
    with pytest.raises(ValueError, match="device"):
        tg.explore(scene, max_steps=1, device=bad)
    with pytest.raises(SystemExit):                          # argparse names it and exits 2
        cli_main(["study", "--device", "gpu", "--out", "unused"])
    with pytest.raises(ValueError, match="device"):
        tg.studies.study.run_sweep(world="planar", objects=["A"], seeds=1, out="unused", device=bad)


def test_a_study_passes_the_device_to_every_run():
    world = tg.sim.paper_objects_2d()["A"]
    for mode in ("visual-tactile", "tactile", "local"):
        assert _explore_kwargs(RunSpec("planar", "A", mode, 0, "out", device="cpu"), world)["device"] == "cpu"
        assert "device" not in _explore_kwargs(RunSpec("planar", "A", mode, 0, "out"), world)


@pytest.mark.skipif(not torch.cuda.is_available(), reason="no CUDA device on this machine (the CPU path is tested)")
@pytest.mark.parametrize("mode", ["visual-tactile", "tactile"])
def test_cuda_run_agrees_with_cpu_over_its_first_steps(mode):
    cpu, gpu = _run(None, mode, steps=4), _run("cuda", mode, steps=4)
    assert gpu.model.train_inputs[0].is_cuda
    # a few steps: the rounding of another device has not yet been amplified by the exploration's chaos
    np.testing.assert_allclose(gpu.contacts, cpu.contacts, rtol=0, atol=1e-6)
    np.testing.assert_allclose(gpu.task_covariance, cpu.task_covariance, rtol=0, atol=1e-6)
