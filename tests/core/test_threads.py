"""torch_threads: the count is bounded by the cores this process may use (issue 33, item 12)."""

import os

import pytest
import torch

from torch_gpioius.cli import main
from torch_gpioius.core.threads import max_threads, torch_threads


def test_max_threads_is_the_cores_this_process_may_use():
    assert max_threads() == len(os.sched_getaffinity(0)) >= 1


def test_a_count_beyond_the_cores_is_refused_before_torch_sees_it():
    before = torch.get_num_threads()
    for n in (max_threads() + 1, 20000, 100000):
        with pytest.raises(ValueError, match=rf"threads: {n} is more than the {max_threads()} cores"):
            with torch_threads(n):
                pass
        assert torch.get_num_threads() == before
    with torch_threads(max_threads()):
        assert torch.get_num_threads() == max_threads()
    assert torch.get_num_threads() == before


def test_the_cli_names_the_bound(capsys):
    """`--threads 100000` ended in a segmentation fault (exit 139), `--threads 20000` inside libgomp."""
    assert main(["fit", "data/example_2d.gpioius", "--threads", "100000"]) == 2
    assert f"threads: 100000 is more than the {max_threads()} cores" in capsys.readouterr().err
