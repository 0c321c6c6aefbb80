"""fit_dataset --out: one fit's files move in together, and a second writer is refused (the folder lock)."""

import json

import pytest

from torch_gpioius.io import offline
from torch_gpioius.io.offline import fit_dataset
from torch_gpioius.io.outputs import FolderLock, StagedFiles

DATA = "data/example_2d.gpioius"


def _snapshot(folder):
    return {p.name: p.read_bytes() for p in folder.iterdir() if p.is_file() and p.name != ".lock"}


def test_a_failed_fit_leaves_the_earlier_fit_whole(tmp_path, monkeypatch):
    out = tmp_path / "fit"
    first = fit_dataset(DATA, out, theta=0.1, noise=0.006, resolution=0.02)
    before = _snapshot(out)
    assert set(before) == {"model.pt", "fit.png", "fit.json"}
    assert json.loads(before["fit.json"])["theta"] == first["theta"]

    def broken(*args, **kwargs):
        raise RuntimeError("figure failed")

    monkeypatch.setattr(offline, "_plot_estimate", broken)   # after model.pt of the second fit was written
    with pytest.raises(RuntimeError, match="figure failed"):
        fit_dataset(DATA, out, theta=0.2, noise=0.006, resolution=0.02)
    assert _snapshot(out) == before                            # model.pt too: not the second fit's
    assert [p.name for p in out.iterdir() if p.name.startswith(".staging")] == []


def test_a_second_fit_into_a_locked_folder_is_refused(tmp_path):
    out = tmp_path / "fit"
    out.mkdir()
    with FolderLock(out, "gpioius fit"):
        with pytest.raises(RuntimeError, match=r"another gpioius fit \(pid \d+\) is writing there"):
            fit_dataset(DATA, out, resolution=0.02)
    assert not (out / "model.pt").exists()


def test_staged_files_move_in_only_on_success(tmp_path):
    (tmp_path / "a.txt").write_text("old a")
    with StagedFiles(tmp_path) as st:
        (st.path / "a.txt").write_text("new a")
        (st.path / "b.txt").write_text("new b")
    assert (tmp_path / "a.txt").read_text() == "new a" and (tmp_path / "b.txt").read_text() == "new b"
    assert sorted(p.name for p in st.moved) == ["a.txt", "b.txt"]
    with pytest.raises(KeyError):
        with StagedFiles(tmp_path) as st:
            (st.path / "a.txt").write_text("newer a")
            raise KeyError("stop")
    assert (tmp_path / "a.txt").read_text() == "new a"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.txt", "b.txt"]
