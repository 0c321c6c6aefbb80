"""The viewer in a real headless Chromium (Debian's package, driven by Playwright; no browser is downloaded)."""

import io
import os
import shutil
import socket
import time
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("viser")

from torch_gpioius.io.datasets import Dataset, save_dataset  # noqa: E402
from torch_gpioius.viewer import RunViewer, run_files  # noqa: E402

CHROMIUM = os.environ.get("GPIOIUS_CHROMIUM") or shutil.which("chromium") or shutil.which("chromium-browser")


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture(scope="module")
def log_2d(tmp_path_factory):
    import torch_gpioius as tg

    path = tmp_path_factory.mktemp("runs") / "A_vt.gpioius"
    tg.explore(tg.sim.paper_objects_2d()["A"], mode="visual-tactile", max_steps=6, log=path, progress=False)
    return path


@pytest.fixture(scope="module")
def dataset_3d(tmp_path_factory):
    """Touches on a 6 cm sphere arriving over 8 steps, and a 9 cm cover seen at step 0."""
    rng = np.random.default_rng(0)

    def sphere(n, r, upper=False):
        d = rng.standard_normal((n, 3))
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        if upper:
            d[:, 2] = np.abs(d[:, 2])
        return r * d

    contacts, free = sphere(16, 0.06, upper=True), sphere(8, 0.12, upper=True)
    outer, outer_free = sphere(60, 0.09), sphere(40, 0.14)
    x = np.concatenate([contacts, free, outer, outer_free])
    y = np.concatenate([np.zeros(16), np.ones(8), np.zeros(60), np.ones(40)])
    task = np.concatenate([np.zeros(24), np.ones(100)]).astype(np.int64)
    step = np.concatenate([np.arange(16) // 2 + 1, np.arange(8) + 1, np.zeros(100)]).astype(np.int64)
    path = tmp_path_factory.mktemp("data") / "sphere.gpioius"
    save_dataset(Dataset(x, y, task, step, meta={"source": "test"}), path)
    return path


def _canvas_png(page) -> np.ndarray:
    from PIL import Image

    return np.asarray(Image.open(io.BytesIO(page.locator("canvas").first.screenshot())).convert("RGB"), dtype=float)


def _wait(predicate, timeout=60.0):
    t0 = time.time()
    while not predicate():
        if time.time() - t0 > timeout:
            raise TimeoutError("the viewer did not get there in time")
        time.sleep(0.2)


def test_viewer_serves_both_dims_without_a_browser(log_2d, dataset_3d, tmp_path):
    for run in (log_2d, dataset_3d):
        viewer = RunViewer(run, port=_free_port())
        try:
            steps = viewer.run.steps
            assert viewer.shown_step == steps[-1] and len(steps) >= 7
            viewer.show(steps[0])
            assert viewer.shown_step == steps[0]
            assert "/estimate" in viewer._handles and "/touch/contacts" in viewer._handles
            if run == log_2d:
                assert "/truth/inner" in viewer._handles        # the built-in scene A is known
            else:
                # a dataset records no similarity; the viewer fills in the fitted one for the steps it visited
                assert np.isfinite(viewer.run.params[steps[-1]]["similarity"])
        finally:
            viewer.close()
    assert run_files(log_2d.parent) == [log_2d]
    with pytest.raises(FileNotFoundError, match="no such run"):
        run_files(tmp_path / "nothing")
    with pytest.raises(FileNotFoundError, match="without .gpioius files"):
        run_files(tmp_path)


@pytest.mark.skipif(CHROMIUM is None, reason="no Chromium installed (apt-get install chromium); CI installs it")
@pytest.mark.parametrize("which", ["2d log", "3d dataset"])
def test_viewer_in_headless_chromium(which, log_2d, dataset_3d, tmp_path):
    playwright = pytest.importorskip("playwright.sync_api")
    run = log_2d if which == "2d log" else dataset_3d
    viewer = RunViewer(run, port=_free_port())
    shots = Path(os.environ.get("GPIOIUS_TEST_ARTIFACTS", tmp_path))
    shots.mkdir(parents=True, exist_ok=True)
    tag = which.replace(" ", "_")
    try:
        with playwright.sync_playwright() as p:
            browser = p.chromium.launch(executable_path=CHROMIUM, args=["--no-sandbox", "--use-angle=swiftshader",
                                                                         "--enable-unsafe-swiftshader"])
            page = browser.new_page(viewport={"width": 1200, "height": 800})
            page.goto(f"http://127.0.0.1:{viewer.port}")
            page.wait_for_selector("canvas", timeout=60_000)
            page.get_by_text("similarity over steps").wait_for(timeout=60_000)
            time.sleep(3.0)                                   # let the scene stream in and render
            last = _canvas_png(page)
            page.screenshot(path=str(shots / f"viewer_{tag}_last.png"))
            # not blank: a rendered scene has many distinct colours, a blank canvas one
            assert last.std() > 5.0 and len(np.unique(last.reshape(-1, 3), axis=0)) > 50
            # the similarity chart draws its lines (a NaN anywhere in uPlot's auto-ranged data blanked it once);
            # a log records both measures at every step (a dataset's are fitted as steps are visited)
            from PIL import Image

            chart = np.asarray(Image.open(io.BytesIO(page.locator(".uplot canvas").first.screenshot()))
                               .convert("RGB"), dtype=float)
            purple = (chart[..., 0] > 90) & (chart[..., 2] > 90) & (chart[..., 1] < 60)      # similarity
            teal = (chart[..., 0] < 60) & (chart[..., 1] > 90) & (chart[..., 2] > 90)        # correlation
            if which == "2d log":
                assert purple.sum() > 20 and teal.sum() > 20, (purple.sum(), teal.sum())
            slider = page.get_by_role("slider").first
            slider.focus()
            page.keyboard.press("Home")                        # move the slider to the first step
            _wait(lambda: viewer.shown_step == viewer.run.steps[0])
            time.sleep(3.0)
            first = _canvas_png(page)
            page.screenshot(path=str(shots / f"viewer_{tag}_first.png"))
            changed = np.abs(first - last).max(axis=-1) > 30
            assert changed.mean() > 0.002, f"the canvas barely changed ({changed.mean():.4%} of pixels)"
            browser.close()
    finally:
        viewer.close()
    print(f"screenshots: {shots}/viewer_{tag}_last.png, {shots}/viewer_{tag}_first.png")
