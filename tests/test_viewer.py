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
import torch_gpioius as tg  # noqa: E402

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
                viewer.show(steps[-1])                          # and where each contact lies from its body
                n = len(steps)                                  # the approach's contact and one per step
                assert f"contacts within 1 cm of the body: {n} of {n}" in viewer.info.content
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
            # the chart's legend names the series without cursor placeholders, and the scene has a colour key
            assert "--" not in page.locator(".u-legend").first.inner_text()
            assert page.get_by_text("colour key").count() == 1 and page.get_by_text("touch: contacts").count() == 1
            # issue 35, item 20: the key was cut off at 900 px; now it ends inside an 800 px window
            last_key = page.get_by_text("true inner shape", exact=True).bounding_box()
            assert last_key is not None and last_key["y"] + last_key["height"] <= 800
            # arrow keys in the step box step the run and leave the camera where it is (a slider thumb also
            # turned the camera)
            client = next(iter(viewer.server.get_clients().values()))
            before = np.array(client.camera.position)
            box = page.get_by_label("step", exact=True)
            box.focus()
            page.keyboard.press("ArrowDown")
            _wait(lambda: viewer.shown_step == viewer.run.steps[-2])
            time.sleep(1.0)
            np.testing.assert_allclose(np.array(client.camera.position), before, atol=1e-9)
            page.get_by_role("button", name="first").click()   # the buttons go to the first step
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


def test_origin_rule():
    from torch_gpioius.viewer import origin_allowed

    assert origin_allowed(None, "127.0.0.1:8080", "127.0.0.1")                  # not a browser page
    for origin, host in (("http://127.0.0.1:8080", "127.0.0.1:8080"), ("http://localhost:8080", "localhost:8080"),
                         ("http://[::1]:8080", "[::1]:8080")):
        assert origin_allowed(origin, host, "127.0.0.1")
    assert not origin_allowed("https://evil.example", "127.0.0.1:8080", "127.0.0.1")     # another site's page
    assert not origin_allowed("http://localhost:9999", "localhost:8080", "127.0.0.1")    # another local port
    assert not origin_allowed("null", "127.0.0.1:8080", "127.0.0.1")                     # sandboxed frames, files
    # DNS rebinding: the attacker's name resolves to 127.0.0.1, so Host and Origin agree, but Host is not ours
    assert not origin_allowed("http://rebind.evil.example:8080", "rebind.evil.example:8080", "127.0.0.1")
    lab = frozenset({"lab-pc", "10.0.0.7"})
    assert origin_allowed("http://lab-pc:8080", "lab-pc:8080", "0.0.0.0", machine=lab)  # bound to all: our names
    assert origin_allowed("http://10.0.0.7:8080", "10.0.0.7:8080", "::", machine=lab)
    # issue 33, item 4: bound to all interfaces, any Host used to pass, so DNS rebinding did too
    assert not origin_allowed("http://evil.example:8080", "evil.example:8080", "0.0.0.0", machine=lab)
    assert not origin_allowed("http://evil.example:8080", "evil.example:8080", "0.0.0.0")   # this machine's names
    assert origin_allowed("http://viz.lab.org:8080", "viz.lab.org:8080", "0.0.0.0", ("viz.lab.org",), lab)
    assert origin_allowed("http://viz.lab.org:8080", "viz.lab.org:8080", "10.0.0.5", ("viz.lab.org",))
    assert origin_allowed("http://10.0.0.5:8080", "10.0.0.5:8080", "10.0.0.5")
    assert not origin_allowed("http://10.0.0.5:8080", None, "10.0.0.5")


def test_a_public_bind_keeps_the_host_check_and_warns(log_2d, capsys):
    """Issue 33, item 4: `--host 0.0.0.0` let a DNS-rebinding handshake (Host and Origin on evil.example) through
    with 101 Switching Protocols; now it gets 403, and the bind is announced as public."""
    from websockets.exceptions import InvalidStatus
    from websockets.sync.client import connect

    from torch_gpioius.viewer import check_hosts, public_bind_warning

    assert public_bind_warning("127.0.0.1") is None and public_bind_warning("::1") is None
    assert "every IPv4 interface" in public_bind_warning("0.0.0.0") and "10.0.0.5" in public_bind_warning("10.0.0.5")
    for bad in ("http://x.org", "x.org:8080", "", "a b"):
        with pytest.raises(ValueError, match="allow_hosts"):
            check_hosts([bad])
    viewer = RunViewer(log_2d, host="0.0.0.0", port=_free_port(), allow_hosts=["viz.lab.example"])
    try:
        def handshake(name, **kw):
            """A browser that reached this machine under ``name`` (the URI's host is the Host header)."""
            sock = socket.create_connection(("127.0.0.1", viewer.port), timeout=10)
            return connect(f"ws://{name}:{viewer.port}", sock=sock, origin=f"http://{name}:{viewer.port}",
                           open_timeout=10, **kw)

        for name in ("evil.example", "rebind.evil.example"):
            with pytest.raises(InvalidStatus) as refused:
                handshake(name).close()
            assert refused.value.response.status_code == 403
        protocol = ["viser-v" + __import__("viser").__version__]
        for name in ("localhost", "viz.lab.example"):            # loopback, and the name the user allowed
            with handshake(name, subprotocols=protocol) as ws:
                assert ws.recv(timeout=10)
    finally:
        viewer.close()


def _own_address() -> str | None:
    """A non-loopback IPv4 address of this machine (the interface a route out would use), or None."""
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        s.connect(("192.0.2.1", 80))                  # no packet is sent: only a route is chosen
        address = s.getsockname()[0]
    except OSError:
        return None
    finally:
        s.close()
    return None if address.startswith("127.") else address


def test_a_public_bind_accepts_the_machines_own_address(log_2d, monkeypatch):
    """Issue 51, item 14: `view --host 0.0.0.0` refused the machine's own IP address (its host name resolved to
    127.0.1.1 alone); `--allow-host '*'` was taken as a literal name."""
    from websockets.sync.client import connect

    import torch_gpioius.viewer as viewer_mod
    from torch_gpioius.viewer import check_hosts, interface_addresses

    with pytest.raises(ValueError, match="wildcards are not accepted"):
        check_hosts(["*"])
    with pytest.raises(ValueError, match="wildcards"):
        check_hosts(["*.lab.example"])
    address = _own_address()
    if address is None:
        pytest.skip("this machine has no non-loopback IPv4 address")
    assert address in interface_addresses()
    # the names a resolver gives may miss the address: the connection's own local address still counts
    monkeypatch.setattr(viewer_mod, "machine_names", lambda: frozenset({"localhost"}))
    viewer = RunViewer(log_2d, host="0.0.0.0", port=_free_port())
    try:
        protocol = ["viser-v" + __import__("viser").__version__]
        sock = socket.create_connection((address, viewer.port), timeout=10)
        with connect(f"ws://{address}:{viewer.port}", sock=sock, origin=f"http://{address}:{viewer.port}",
                     open_timeout=10, subprotocols=protocol) as ws:
            assert ws.recv(timeout=10)
    finally:
        viewer.close()


def test_cross_site_pages_cannot_open_the_websocket(log_2d):
    """A page of another origin is refused at the handshake (403) and sees nothing of the run; the viewer's own
    page gets its connection."""
    from websockets.exceptions import InvalidStatus
    from websockets.sync.client import connect

    viewer = RunViewer(log_2d, port=_free_port())
    try:
        uri = f"ws://127.0.0.1:{viewer.port}"
        with pytest.raises(InvalidStatus) as refused:
            connect(uri, origin="https://evil.example", open_timeout=10).close()
        assert refused.value.response.status_code == 403
        with connect(uri, origin=f"http://127.0.0.1:{viewer.port}", subprotocols=["viser-v" + __import__(
                "viser").__version__], open_timeout=10) as ws:
            assert ws.recv(timeout=10)                        # the scene streams to the viewer's own page
    finally:
        viewer.close()


def test_bad_ports_and_unreadable_runs_fail_fast_and_are_named(log_2d, tmp_path, capsys):
    from torch_gpioius.cli import main
    from torch_gpioius.viewer import check_port

    for port in (70000, -5, 1.5, True):
        with pytest.raises(ValueError, match=r"port: must be an integer in \[0, 65535\]"):
            check_port(port)
    t0 = time.time()
    assert main(["view", str(log_2d), "--port", "70000", "--no-browser"]) == 2      # used to hang for ever
    assert "port: must be an integer" in capsys.readouterr().err and time.time() - t0 < 30
    study = tmp_path / "study"
    (study / "logs").mkdir(parents=True)
    shutil.copy(log_2d, study / "logs" / "good.gpioius")
    (study / "logs" / "bad.gpioius").write_bytes(b"GPIOIUS\x00\x00\x01garbage")
    viewer = RunViewer(study, port=_free_port())
    try:
        assert [p.name for p in viewer.files] == ["good.gpioius"]                  # the corrupt run is left out
        assert "bad.gpioius" in str(list(viewer.skipped)) and "no header record" in next(iter(viewer.skipped.values()))
    finally:
        viewer.close()
    (study / "logs" / "good.gpioius").unlink()
    from torch_gpioius.io.datasets import DatasetError
    with pytest.raises(DatasetError, match="no readable run: .*bad.gpioius"):
        RunViewer(study, port=_free_port())


def test_hosts_that_cannot_be_served_are_refused_before_anything_starts(log_2d, capsys):
    """Issue 60, items 8 and 16: `view --host "not a host"` (or 256.1.1.1, example.com, an address of another machine,
    a URL) printed "(viser) Server stopped" and never exited; `--host '*'` served a URL of http://*; `--host ::` was
    called "every interface" but serves IPv6 only."""
    from torch_gpioius.cli import main
    from torch_gpioius.viewer import check_host, public_bind_warning

    for host, match in (("not a host", "neither an IP address nor a host name"), ("256.1.1.1", "does not resolve"),
                        ("no-such-host.invalid", "does not resolve"), ("192.0.2.1", "not an address of this machine"),
                        ("http://127.0.0.1:8080/", "is a URL or path"), ("*", "0.0.0.0 serves every IPv4 interface"),
                        ("", "expected an interface")):
        with pytest.raises(ValueError, match=match):
            check_host(host)
        t0 = time.time()
        assert main(["view", str(log_2d), "--host", host, "--no-browser", "--port", "0"]) == 2
        assert match in capsys.readouterr().err and time.time() - t0 < 30
    assert check_host("127.0.0.1") == "127.0.0.1" and check_host("0.0.0.0") == "0.0.0.0"
    assert check_host("localhost") == "localhost"
    assert "every IPv4 interface" in public_bind_warning("0.0.0.0")
    assert "every IPv6 interface (IPv4 clients cannot connect" in public_bind_warning("::")


def test_the_initial_view_holds_the_whole_object():
    """The camera stands where the bounding sphere fills half the view's height (it used to open zoomed in)."""
    import math

    from torch_gpioius.viewer import frame_distance

    for radius, fov in ((0.1, math.radians(75)), (0.5, math.radians(50))):
        d = frame_distance(radius, fov, fill=0.5)
        assert math.tan(math.asin(radius / d)) == pytest.approx(0.5 * math.tan(fov / 2), rel=1e-12)


def test_a_step_without_an_estimate_is_named_in_the_panel(log_2d, monkeypatch):
    """Issue 33, item 5: an empty picture for a step whose estimate has no surface said nothing."""
    viewer = RunViewer(log_2d, port=_free_port())
    try:
        viewer.show(viewer.run.steps[-1])
        assert "No estimate" not in viewer.info.content
        monkeypatch.setattr(viewer, "_estimate", lambda k: ([], None, 1.0))      # no curve at this step
        viewer.show(viewer.run.steps[0])
        assert "**No estimate at this step:**" in viewer.info.content
    finally:
        viewer.close()


def test_a_malformed_message_closes_its_connection_with_one_line(log_2d, capfd):
    """Issue 33, item 16: a malformed WebSocket message printed a traceback in the viewer's terminal."""
    from websockets.sync.client import connect

    viewer = RunViewer(log_2d, port=_free_port())
    protocol = ["viser-v" + __import__("viser").__version__]
    try:
        uri = f"ws://127.0.0.1:{viewer.port}"
        with connect(uri, origin=f"http://127.0.0.1:{viewer.port}", subprotocols=protocol, open_timeout=10) as ws:
            ws.recv(timeout=10)
            ws.send(b"\x93\x01\x02garbage")                      # not a viser message
            err = []
            _wait(lambda: err.append(capfd.readouterr().err) or "cannot read" in "".join(err), timeout=20)
        with connect(uri, origin=f"http://127.0.0.1:{viewer.port}", subprotocols=protocol, open_timeout=10) as ws:
            assert ws.recv(timeout=10)                              # the server goes on serving
    finally:
        viewer.close()
    err = "".join(err) + capfd.readouterr().err
    assert "closed the connection from 127.0.0.1" in err and "DecodeError" in err
    assert "Traceback" not in err and "connection handler failed" not in err


def test_a_study_folder_opens_on_a_visual_tactile_run_and_says_what_does_not_apply(tmp_path):
    """Issue 35, item 20: a study folder opened on the touch-only run, with a red dot at similarity 0 where the
    similarity does not apply; the truth checkbox did nothing for a run without a known truth."""
    study = tmp_path / "study"
    (study / "logs").mkdir(parents=True)
    for mode in ("tactile", "visual-tactile"):
        tg.explore(tg.sim.paper_objects_2d()["A"], mode=mode, max_steps=3, log=study / "logs" / f"A_{mode}.gpioius")
    viewer = RunViewer(study, port=_free_port())
    try:
        assert viewer.run.path.name == "A_visual-tactile.gpioius"
        assert viewer.run_dropdown.value == "A_visual-tactile.gpioius"
        viewer._show_run(next(p for p in viewer.files if p.name == "A_tactile.gpioius"))
        mark = viewer.plot.data[3]
        assert np.isnan(mark).all()                          # no "this step" dot at 0
        assert "do not apply (touch only)" in viewer.info.content
        assert not viewer.layers["true shapes"].disabled     # the built-in scene A is known
    finally:
        viewer.close()


def test_a_run_without_a_known_truth_disables_its_checkbox(dataset_3d):
    viewer = RunViewer(dataset_3d, port=_free_port())
    try:
        assert viewer.layers["true shapes"].disabled and "true shape: not known for this run" in viewer.info.content
    finally:
        viewer.close()


@pytest.mark.parametrize("value", [float("nan"), "abc", [1, 2], None])
def test_a_step_typed_as_nonsense_is_one_line_and_keeps_the_step(log_2d, capfd, value):
    """Issue 51, item 18: the step control given NaN, a string or a list logged "Task exception was never
    retrieved" (viser casts the value inside its own message handler)."""
    import asyncio

    from viser import _messages

    viewer = RunViewer(log_2d, port=_free_port())
    try:
        before = viewer.step_box.value
        handler = viewer.server.gui._websock_interface._incoming_handlers[_messages.GuiUpdateMessage][0]
        message = _messages.GuiUpdateMessage(uuid=viewer.step_box._impl.uuid, updates={"value": value})
        asyncio.run(handler(0, message))                   # no exception escapes the handler
        assert viewer.step_box.value == before
    finally:
        viewer.close()
    assert "gpioius view: ignored a control update it cannot use" in capfd.readouterr().err


def test_a_scene_file_runs_truth_is_shown_while_the_file_is_unchanged(tmp_path):
    """Issue 51, item 22: the viewer said "true shape: not known for this run" for a scene-file run whose fig9 drew
    the true surface."""
    from tests.scenes import ball_scene
    from torch_gpioius.io.runs import known_truth, load_run
    from torch_gpioius.sim.scenefile import load_scene

    path = ball_scene(tmp_path)
    log = tmp_path / "ball.gpioius"
    tg.explore(load_scene(path), mode="tactile", max_travel=0.02, metrics_every=100, log=log, progress=False)
    meta = load_run(log).meta
    assert meta["scene_file"]["path"] == str(path.resolve())
    truth = known_truth(meta)
    assert truth is not None and abs(truth["inner"].bounding_sphere.primitive.radius - 0.06) < 0.002
    viewer = RunViewer(log, port=_free_port())
    try:
        assert "/truth/inner" in viewer._handles and not viewer.layers["true shapes"].disabled
    finally:
        viewer.close()
    path.write_text(path.read_text().replace("gap = 0.008", "gap = 0.01"))      # another scene now: not this run's
    assert known_truth(meta) is None


def test_a_taken_port_is_named_with_the_one_served(log_2d, monkeypatch, capsys):
    """Issue 51, item 24: `view --port 8770` with the port taken served on 8771 and said nothing."""
    import torch_gpioius.viewer as viewer_mod

    taken = socket.socket()
    taken.bind(("127.0.0.1", 0))
    taken.listen(1)
    port = taken.getsockname()[1]
    monkeypatch.setattr(viewer_mod.time, "sleep", lambda s: (_ for _ in ()).throw(KeyboardInterrupt))
    try:
        with pytest.raises(KeyboardInterrupt):
            viewer_mod.serve(log_2d, port=port, open_browser=False)
    finally:
        taken.close()
    err = capsys.readouterr().err
    assert f"port {port} is taken; serving on port " in err
    assert viewer_mod.port_note(0, 51234) is None and viewer_mod.port_note(8080, 8080) is None


def test_the_viewer_says_what_the_touches_moved_each_camera_capture_by():
    """Issue 63, item 2: from the step that corrected the captures on (a log), or for a whole dataset (a fit on files),
    the info panel names each capture's correction and the contacts' misfit; a run without one says nothing of it."""
    from types import SimpleNamespace

    fix = {"captures": [{"size_mm": 6.0, "angle_deg": 1.25}, {"size_mm": 5.3, "angle_deg": 0.69}],
           "misfit_before_mm": 3.0, "misfit_after_mm": 0.84}
    log = SimpleNamespace(meta={}, steps=[0, 1, 2, 3], params={2: {"camera_corrections": fix}})
    assert RunViewer._camera_corrections(log, 1) == ""
    line = RunViewer._camera_corrections(log, 3)
    assert "corrected from the touches at step 2: 6.0 mm 1.25 deg, 5.3 mm 0.69 deg" in line and "3.0 -> 0.8 mm" in line
    files = SimpleNamespace(meta={"camera_corrections": fix}, steps=[0], params={})
    assert "corrected from the touches: 6.0 mm" in RunViewer._camera_corrections(files, 0)
