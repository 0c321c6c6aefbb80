"""Interactive viewer of a run in the browser, on `viser <https://viser.studio>`_ (the ``viewer`` extra).

``gpioius view run.gpioius`` serves a local page that shows, for the step picked with a slider:

* the camera's point cloud (outer surface seen, grey) and the free space in front of it (light blue);
* the contacts (black) and free-space points (cyan) touched so far, and the fingertip's path (orange);
* the estimated inner surface {mu_in = 0} coloured by its posterior variance (white: certain, purple: the prior),
  a mesh in 3-D, a curve in the z = 0 plane in 2-D;
* the true inner (green) and outer (grey) shapes when the run names a built-in world;
* the similarity and correlation over the steps, with the current step marked.

A study folder (with ``logs/``) gets a dropdown of its runs; every run is read and checked before the address is
printed (a run that cannot be read is named and left out), so a browser never connects to a half-loaded viewer.
Estimates are computed on demand with the run's own learned K_t at each step
(:meth:`torch_gpioius.io.runs.RunHistory.model_at`) and cached.

The step is picked with a number box (arrow keys or typing) and first / previous / next / last buttons: arrow keys
in a form field never move the 3-D camera, while viser's slider thumb passes them on to the camera as well.

**Security.** The page binds 127.0.0.1 unless told otherwise (``host``). Its WebSocket refuses a handshake whose
``Origin`` is another site (cross-site WebSocket hijacking: any page the user opens could otherwise read the run and
drive the GUI) and one whose ``Host`` is not this machine's (DNS rebinding); see :func:`origin_allowed`.
"""

from __future__ import annotations

import math
import os
import sys
import threading
import time
import warnings
import webbrowser
from pathlib import Path

import numpy as np

__all__ = ["RunViewer", "serve", "run_files", "origin_allowed", "check_port", "check_host", "check_hosts",
           "machine_names",
           "public_bind_warning", "COLOUR_KEY"]

_GREY, _LIGHT_BLUE, _BLACK, _CYAN, _ORANGE = (
    (150, 150, 150),
    (150, 200, 255),
    (20, 20, 20),
    (0, 190, 210),
    (255, 140, 0),
)
_PAD, _PAD_OLD = (200, 30, 120), (230, 170, 200)      # the gel pad's outline: this step's, earlier ones
_GREEN = (30, 160, 60)
_PURPLE = (120, 60, 170)                               # points known to lie inside a body (labels below zero)


def run_files(source: str | os.PathLike) -> list[Path]:
    """The runs a source names: the file itself, or a study folder's ``logs/*.gpioius`` (else ``*.gpioius``).

    Raises:
        FileNotFoundError: the path does not exist, or a folder holds no ``.gpioius`` file.
    """
    p = Path(source)
    if p.is_file():
        return [p]
    if p.is_dir():
        files = sorted((p / "logs").glob("*.gpioius")) or sorted(p.glob("*.gpioius"))
        if not files:
            raise FileNotFoundError(f"{p}: a folder without .gpioius files (expected a study folder with logs/)")
        return files
    raise FileNotFoundError(f"{p}: no such run, dataset or study folder")


def _segments(polyline: np.ndarray) -> np.ndarray:
    """`(m - 1, 2, 3)` segments of a `(m, d)` polyline (2-D lifted to z = 0)."""
    p = np.asarray(polyline, dtype=np.float64)
    if p.shape[1] == 2:
        p = np.column_stack([p, np.zeros(len(p))])
    return np.stack([p[:-1], p[1:]], axis=1)


def _lift(x: np.ndarray) -> np.ndarray:
    x = np.asarray(x, dtype=np.float64)
    return np.column_stack([x, np.zeros(len(x))]) if x.shape[1] == 2 else x


#: What each colour in the scene is (the GUI shows it as a key).
COLOUR_KEY = (("camera: seen outer surface", _GREY), ("camera: free space in front of it", _LIGHT_BLUE),
              ("touch: contacts", _BLACK), ("touch: free space", _CYAN),
              ("inside points behind contacts or the seen surface (label < 0)", _PURPLE), ("fingertip path", _ORANGE),
              ("gel pad at this step (earlier ones paler; patch runs)", _PAD), ("true inner shape", _GREEN))

_LOOPBACK = ("localhost", "127.0.0.1", "::1")


def check_port(port) -> int:
    """A TCP port to serve on: an integer in [0, 65535] (0: any free port).

    Raises:
        ValueError: anything else (a port of 70000 or -5 used to crash viser's server thread and hang the command).
    """
    if isinstance(port, bool) or not isinstance(port, int) or not 0 <= port <= 65535:
        raise ValueError(f"port: must be an integer in [0, 65535] (0: any free port), got {port!r}")
    return port


def machine_names() -> frozenset[str]:
    """The names and addresses by which other machines reach this one (host name, FQDN, and their addresses),
    lower-case; what a viewer bound to all interfaces accepts as ``Host`` besides loopback and the user's names."""
    import socket

    names = {socket.gethostname(), socket.getfqdn()}
    for name in list(names):
        try:
            names.update(info[4][0] for info in socket.getaddrinfo(name, None))
        except OSError:                  # a host name that does not resolve: the name itself still counts
            pass
    # the host name often resolves to 127.0.x.x alone (Debian's /etc/hosts): the interfaces' own addresses too
    names.update(interface_addresses())
    return frozenset(n.lower() for n in names if n)


def interface_addresses() -> set[str]:
    """This machine's interface addresses (IPv4 by ``SIOCGIFADDR``, IPv6 from ``/proc/net/if_inet6``); empty where
    the platform offers neither (the standard library has no portable call for it)."""
    import ipaddress
    import socket
    import struct

    found: set[str] = set()
    try:
        import fcntl

        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            for _, name in socket.if_nameindex():
                try:
                    packed = fcntl.ioctl(s.fileno(), 0x8915, struct.pack("256s", name[:15].encode()))   # SIOCGIFADDR
                    found.add(socket.inet_ntoa(packed[20:24]))
                except OSError:          # an interface without an IPv4 address
                    pass
    except (ImportError, OSError, AttributeError):
        pass
    try:
        with open("/proc/net/if_inet6") as f:
            for line in f:
                raw = line.split()[0]
                found.add(str(ipaddress.IPv6Address(bytes.fromhex(raw))))
    except (OSError, ValueError, IndexError):
        pass
    return found


def _all_interfaces(bound_host: str) -> bool:
    return bound_host in ("0.0.0.0", "::", "")


def origin_allowed(origin: str | None, host_header: str | None, bound_host: str,
                   allowed_hosts: tuple[str, ...] | frozenset[str] = (), machine: frozenset[str] | None = None) -> bool:
    """Whether a WebSocket handshake may proceed (RFC 6455, section 10.2).

    * No ``Origin`` header: not a browser page (browsers always send one): allowed.
    * The ``Host`` the client asked for must name this machine: a loopback name, the interface the viewer was bound
      to, this machine's own names and addresses when bound to all interfaces (``0.0.0.0`` / ``::``;
      :func:`machine_names`), or a name in ``allowed_hosts`` (``gpioius view --allow-host``: a DNS alias, a reverse
      proxy). Any other name is refused on every bind: a page that re-points its own domain name at this machine
      (DNS rebinding) reaches it with its own name as ``Host``.
    * The ``Origin`` must be the viewer's own page: scheme http(s) and the same host and port as ``Host``. Any
      other site's page is refused (cross-site WebSocket hijacking).

    Args:
        origin: the handshake's ``Origin`` header (None where absent).
        host_header: its ``Host`` header (None where absent).
        bound_host: the interface the viewer serves on.
        allowed_hosts: further host names the user named.
        machine: this machine's names (default: :func:`machine_names`, looked up when bound to all interfaces).
    """
    from urllib.parse import urlsplit

    if origin is None:
        return True
    if not host_header:
        return False
    try:
        o = urlsplit(origin)
        h = urlsplit(f"//{host_header}")
        o_port = o.port or (443 if o.scheme == "https" else 80)
        h_port = h.port or 80
    except ValueError:
        return False
    allowed = set(_LOOPBACK) | {a.strip("[]").lower() for a in allowed_hosts}
    if not _all_interfaces(bound_host):
        allowed.add(bound_host.strip("[]").lower())
    else:
        allowed |= machine_names() if machine is None else machine
    return (o.scheme in ("http", "https") and h.hostname in allowed and o.hostname == h.hostname
            and o_port == h_port)


def check_hosts(hosts) -> tuple[str, ...]:
    """Host names for ``allow_hosts``: non-empty names or addresses, without scheme, port or path.

    Raises:
        ValueError: naming the bad entry.
    """
    if isinstance(hosts, str):
        hosts = (hosts,)
    out = []
    for h in hosts or ():
        if isinstance(h, str) and ("*" in h or "?" in h):
            raise ValueError(f"allow_hosts: {h!r}: wildcards are not accepted; a wildcard would let any site's page "
                             "that points its own name at this machine drive the viewer (DNS rebinding). Name each "
                             "host, e.g. --allow-host lab-pc.example.org")
        if not isinstance(h, str) or not h.strip() or any(c in h for c in "/@ ") or h.count(":") == 1:
            raise ValueError(f"allow_hosts: {h!r} is not a host name or address (give it without scheme or port, "
                             "e.g. lab-pc.example.org)")
        out.append(h.strip().strip("[]").lower())
    return tuple(out)


def check_host(host) -> str:
    """The interface to serve on, checked before anything starts: an address of this machine (IPv4 or IPv6, in
    brackets or not), ``0.0.0.0`` (every IPv4 interface), ``::`` (every IPv6 one), or a host name that resolves to an
    address of this machine.

    A name that does not resolve, an address that is not this machine's, a URL or a wildcard used to stop viser's
    server thread ("(viser) Server stopped") while the command waited forever; ``*`` served a URL of ``http://*``.

    Returns:
        the host as viser takes it (an IPv6 address without brackets).

    Raises:
        ValueError: naming the host and what is wrong with it.
    """
    import ipaddress
    import socket

    if not isinstance(host, str) or not host.strip():
        raise ValueError(f"--host: expected an interface's address or name, got {host!r}")
    text = host.strip()
    if text in ("*", "any", "all"):
        raise ValueError(f"--host: {text!r} is not an interface; 0.0.0.0 serves every IPv4 interface, :: every IPv6 "
                         "one (other machines can then connect)")
    if "/" in text or "://" in text:
        raise ValueError(f"--host: {text!r} is a URL or path; give an interface's address or name without scheme, "
                         "port or path (127.0.0.1, 0.0.0.0, lab-pc)")
    bare = text[1:-1] if text.startswith("[") and text.endswith("]") else text
    try:
        addresses = [str(ipaddress.ip_address(bare))]
    except ValueError:
        if not all(c.isalnum() or c in "-._" for c in bare) or bare.startswith(("-", ".")):
            raise ValueError(f"--host: {text!r} is neither an IP address nor a host name") from None
        try:
            addresses = sorted({info[4][0] for info in socket.getaddrinfo(bare, None, type=socket.SOCK_STREAM)})
        except OSError as exc:
            raise ValueError(f"--host: {text!r} does not resolve to an address ({exc.strerror or exc}); give one of "
                             "this machine's addresses or names") from None
    for address in addresses:
        family = socket.AF_INET6 if ":" in address else socket.AF_INET
        try:
            with socket.socket(family, socket.SOCK_STREAM) as probe:
                probe.bind((address, 0))
            return bare
        except OSError:
            continue
    raise ValueError(f"--host: {text!r} ({', '.join(addresses)}) is not an address of this machine, so nothing can be "
                     "served there; give one of its interfaces' addresses, 127.0.0.1 or 0.0.0.0")


def public_bind_warning(host: str) -> str | None:
    """A warning for a bind that other machines can reach (None for loopback)."""
    if host.strip("[]").lower() in _LOOPBACK:
        return None
    where = {"0.0.0.0": "every IPv4 interface", "::": "every IPv6 interface (IPv4 clients cannot connect there; "
             "0.0.0.0 serves IPv4)", "": "every interface"}.get(host.strip("[]"), host)
    return (f"gpioius view: warning: serving on {where}: anyone who can reach this machine on the network can open "
            "the run and drive the page (there is no password); serve on 127.0.0.1 and use an SSH tunnel where you "
            "can. Pages are accepted only under this machine's names and --allow-host names.")


class _Proxy:
    """An attribute proxy: ``overrides`` first, then the wrapped object."""

    def __init__(self, wrapped, **overrides) -> None:
        self._wrapped, self._overrides = wrapped, overrides

    def __getattr__(self, name):
        if name in self._overrides:
            return self._overrides[name]
        return getattr(self._wrapped, name)


def _install_origin_check(bound_host: str, allowed_hosts: tuple[str, ...] = ()) -> None:
    """Make the WebSocket server of viewers created from now on check the handshake with :func:`origin_allowed`.

    viser (1.1) has no option for it: its ``WebsockServer`` calls ``websockets.asyncio.server.serve`` through the
    ``websockets`` name of its ``viser.infra._infra`` module. That one name is replaced by a proxy whose ``serve``
    wraps viser's own ``process_request`` with the check; nothing else in viser or in ``websockets`` changes.
    """
    import http

    from viser.infra import _infra

    real = getattr(_infra.websockets, "_wrapped_websockets", _infra.websockets)
    real_serve = real.asyncio.server.serve
    machine = machine_names() if _all_interfaces(bound_host) else frozenset()

    def serve(handler, host, port, *args, process_request=None, **kwargs):
        def check(connection, request):
            h = request.headers
            # bound to every interface, the address the client reached is one of this machine's by definition
            here = machine | _local_address(connection) if _all_interfaces(bound_host) else machine
            if h.get("Upgrade", "").lower() == "websocket" and (
                    len(h.get_all("Host")) != 1 or len(h.get_all("Origin")) > 1      # ambiguous: refused
                    or not origin_allowed(h["Origin"] if "Origin" in h else None, h["Host"], bound_host,
                                          allowed_hosts, here)):
                return connection.respond(http.HTTPStatus.FORBIDDEN, "gpioius view: cross-origin WebSocket refused\n")
            return process_request(connection, request) if process_request is not None else None

        async def guarded(connection):
            # one client's unreadable message (a malformed frame, garbage MessagePack) ends that connection with one
            # line here, not a traceback from websockets' logger; the server and other pages go on
            try:
                await handler(connection)
            except Exception as exc:
                print(f"gpioius view: closed the connection from {_peer(connection)}: it sent a message the viewer "
                      f"cannot read ({type(exc).__name__}: {' '.join(str(exc).split())[:200]})", file=sys.stderr,
                      flush=True)

        return real_serve(guarded, host, port, *args, process_request=check, **kwargs)

    server_mod = _Proxy(real.asyncio.server, serve=serve)
    proxy = _Proxy(real, asyncio=_Proxy(real.asyncio, server=server_mod), _wrapped_websockets=real)
    _infra.websockets = proxy


def _guard_gui_updates(server) -> None:
    """Make a GUI update the viewer cannot use (a step typed as NaN, a string or a list) end in one line, not in an
    asyncio task's unretrieved exception.

    viser (1.1) casts each update to its control's type inside its own message handler (``int("abc")`` raises
    there), before any callback of ours runs, and offers no hook for it: its handler is swapped for one that calls it
    and reports what it refuses; the control keeps its value."""
    from viser import _messages

    api = server.gui
    original = api._handle_gui_updates

    async def guarded(client_id, message) -> None:
        try:
            await original(client_id, message)
        except (TypeError, ValueError, OverflowError, AssertionError) as exc:
            shown = " ".join(repr(message.updates).split())[:120]
            print(f"gpioius view: ignored a control update it cannot use ({type(exc).__name__}: {shown})",
                  file=sys.stderr, flush=True)

    api._websock_interface.unregister_handler(_messages.GuiUpdateMessage, original)
    api._websock_interface.register_handler(_messages.GuiUpdateMessage, guarded)


def _local_address(connection) -> frozenset[str]:
    """The address a client connected to (empty where the transport has none)."""
    try:
        return frozenset({str(connection.local_address[0]).lower()})
    except Exception:                      # pragma: no cover - a transport without an address
        return frozenset()


def _peer(connection) -> str:
    try:
        host, port = connection.remote_address[:2]
        return f"{host}:{port}"
    except Exception:                      # pragma: no cover - a transport without an address
        return "a client"


class RunViewer:
    """A viser server showing one or more runs (see the module docstring).

    Args:
        source: a log, a dataset, or a study folder.
        host: interface to serve on.
        port: TCP port (viser moves to the next free one if taken; see :attr:`port`).
        resolution: grid spacing of the estimates [m] (default 5 mm in 2-D, 1.5 cm in 3-D).
        allow_hosts: host names, besides this machine's own, under which a browser page may connect (a DNS
            alias or a reverse proxy; see :func:`origin_allowed`).

    Attributes:
        server: the ``viser.ViserServer``.
        port: the port actually served.
        step_box: the GUI number box of the step (an index into the run's steps).
        skipped: runs of the source that could not be read, ``{path: reason}``.
    """

    def __init__(self, source: str | os.PathLike, *, host: str = "127.0.0.1", port: int = 8080,
                 resolution: float | None = None, progress: bool = False, allow_hosts=()) -> None:
        try:
            import viser
        except ImportError as exc:  # pragma: no cover - extra missing
            from .core.extras import install_hint

            raise ImportError(f"gpioius view needs the 'viewer' extra: {install_hint('viewer')}") from exc
        from .io.datasets import DatasetError
        from .io.runs import load_run

        check_port(port)
        host = check_host(host)
        allow_hosts = check_hosts(allow_hosts)
        if resolution is not None:
            from .core.validation import as_float

            resolution = as_float(resolution, "resolution", lo=1e-3, hi=0.5, unit="m")
        files = run_files(source)
        self._runs: dict[Path, object] = {}
        #: runs that could not be read: ``{path: reason}`` (left out of the dropdown, listed in the panel)
        self.skipped: dict[Path, str] = {}
        for i, f in enumerate(files):             # every run is read and checked before anything is served
            if progress:
                print(f"gpioius view: reading {f.name} ({i + 1}/{len(files)})", file=sys.stderr, flush=True)
            try:
                self._runs[f] = load_run(f)
            except DatasetError as exc:
                self.skipped[f] = " ".join(str(exc).split())
        self.files = [f for f in files if f in self._runs]
        if not self.files:
            raise DatasetError("gpioius view: no readable run: " + "; ".join(self.skipped.values()))
        self._cache: dict[tuple[Path, int], tuple] = {}
        self._lock = threading.RLock()
        self._handles: dict[str, object] = {}
        self._y_range: tuple[float, float] | None = None
        self.resolution = resolution
        self.host = host
        self.run = self._runs[self.files[0]]
        _install_origin_check(host, allow_hosts)
        self.server = viser.ViserServer(host=host, port=port, verbose=False)
        _guard_gui_updates(self.server)
        self.port = self.server.get_port()
        self.server.scene.set_up_direction("+z")
        self._build_gui()
        self._show_run(self._first_run())

    # ---------------------------------------------------------------------------------------------------- data
    def _get(self, path: Path):
        return self._runs[path]

    def _estimate(self, k: int):
        key = (self.run.path, k)
        if key not in self._cache:
            from .geometry.surfaces import data_bounds
            from .io.runs import estimate_surface
            from .geometry.metrics import prior_variance
            from .models.gpiois import UnidentifiedSimilarityWarning

            with warnings.catch_warnings():   # a dataset's step 0 has no touch yet: its similarity is unidentified
                warnings.simplefilter("ignore", UnidentifiedSimilarityWarning)
                model = self.run.model_at(k)
            p = self.run.params.setdefault(k, {})
            if not math.isfinite(p.get("similarity", math.nan)) and hasattr(model, "similarity"):
                # datasets record no similarity: fill in what the fitted model says, as the steps are visited
                p["similarity"], p["correlation"] = float(model.similarity), float(model.correlation)
                i = self.run.steps.index(k)
                self._series[1][i], self._series[2][i] = p["similarity"], p["correlation"]
            ds = self.run.states[k]
            res = self.resolution or (0.005 if self.run.dim == 2 else 0.015)
            inner = ds.task == 0
            if not (inner & (ds.y == 0)).any():
                self._cache[key] = (None, None, 1.0)
            else:
                surface, var = estimate_surface(model, data_bounds(ds.x), res, 0)
                self._cache[key] = (surface, var, prior_variance(model, 0))
        return self._cache[key]

    # ---------------------------------------------------------------------------------------------------- GUI
    def _build_gui(self) -> None:
        from viser import uplot

        gui = self.server.gui
        self.run_dropdown = gui.add_dropdown("run", [p.name for p in self.files],
                                             initial_value=self._first_run().name, visible=len(self.files) > 1)
        # a number box, not a slider: arrow keys in a form field step it without also turning the camera
        self.step_box = gui.add_number("step", initial_value=0, min=0, max=1, step=1)
        self.step_buttons = gui.add_button_group("steps", ("first", "previous", "next", "last"))
        self.info = gui.add_markdown("")
        if self.skipped:
            gui.add_markdown("**Left out** (unreadable): " + "; ".join(f"`{p.name}`: {why}" for p, why in
                                                                     self.skipped.items()))
        self.layers = {name: gui.add_checkbox(name, True) for name in
                       ("point cloud", "touches", "path", "estimate", "true shapes")}
        # the key right under the layers it explains, in two columns: below the chart it was cut off at 900 px
        gui.add_html(_colour_key_html())
        self.plot = gui.add_uplot(data=(np.zeros(1), np.zeros(1), np.zeros(1), np.zeros(1)),
                                  series=(uplot.Series(label="step"),
                                          uplot.Series(label="similarity", stroke="purple", width=2),
                                          uplot.Series(label="correlation", stroke="teal", width=2),
                                          uplot.Series(label="this step", stroke="red", width=0,
                                                       points={"show": True, "size": 8, "fill": "red"})),
                                  title="similarity over steps", aspect=1.6,
                                  scales={"x": uplot.Scale(time=False)},
                                  axes=(uplot.Axis(label="step", incrs=[1, 2, 5, 10, 20, 50, 100, 200, 500, 1000]),
                                        uplot.Axis()),
                                  legend=uplot.Legend(live=False))

        @self.run_dropdown.on_update
        def _(_event) -> None:
            self._show_run(next(p for p in self.files if p.name == self.run_dropdown.value))

        @self.step_box.on_update
        def _(_event) -> None:
            self.show(self.run.steps[self._step_index()])

        @self.step_buttons.on_click
        def _(_event) -> None:
            i, last = self._step_index(), len(self.run.steps) - 1
            target = {"first": 0, "previous": max(i - 1, 0), "next": min(i + 1, last), "last": last}
            self.step_box.value = target[self.step_buttons.value]

        for box in self.layers.values():
            @box.on_update
            def _(_event) -> None:
                self.show(self.run.steps[self._step_index()])

    def _first_run(self) -> Path:
        """The run shown first: a study folder's first visual-tactile run (the touch-only one has no similarity to
        show), else the first file."""
        return next((f for f in self.files if "visual-tactile" in f.name), self.files[0])

    def _step_index(self) -> int:
        """The step box's value as an index into the run's steps (clamped: a typed number may be anything)."""
        try:
            v = int(round(float(self.step_box.value)))
        except (TypeError, ValueError):
            v = 0
        return min(max(v, 0), len(self.run.steps) - 1)

    def _show_run(self, path: Path) -> None:
        with self._lock:
            self.run = self._get(path)
            steps = self.run.steps
            self.server.scene.reset()
            self._handles = {}
            truth = self._truth()
            if truth is not None:
                self._draw_truth(truth)
            # nothing to show for a run whose world is unknown (a dataset, a real robot): say so, do not pretend
            self.layers["true shapes"].disabled = truth is None
            self._frame_camera()
            s, r = self.run.series("similarity"), self.run.series("correlation")
            self._series = (np.asarray(steps, dtype=np.float64), s, r)
        self.step_box.max = max(len(steps) - 1, 1)
        self.step_box.value = len(steps) - 1
        self.show(steps[-1])

    def _frame_camera(self) -> None:
        """Point the initial camera at the run's observations, from above in 2-D and from a diagonal in 3-D, far
        enough that their bounding sphere fills at most half the view's height (:func:`frame_distance`): the whole
        object is in view and clear of the control panel on the right."""
        x = self.run.states[self.run.steps[-1]].x
        lo, hi = x.min(axis=0), x.max(axis=0)
        centre = _lift(((lo + hi) / 2)[None])[0]
        radius = max(0.5 * float(np.linalg.norm(hi - lo)), 1e-3)
        cam = self.server.initial_camera
        distance = frame_distance(radius, float(cam.fov))
        cam.look_at = tuple(centre)
        if self.run.dim == 2:
            cam.up = (0.0, 1.0, 0.0)
            cam.position = tuple(centre + [0.0, -1e-3 * distance, distance])
        else:
            cam.up = (0.0, 0.0, 1.0)
            view = np.array([-0.8, -0.9, 0.7])
            cam.position = tuple(centre + distance * view / np.linalg.norm(view))
        for client in self.server.get_clients().values():
            client.camera.look_at, client.camera.position = cam.look_at, cam.position

    def _truth(self):
        from .io.runs import known_truth

        if not hasattr(self.run, "_truth"):
            self.run._truth = known_truth(self.run.meta)
        return self.run._truth

    def _draw_truth(self, truth: dict) -> None:
        scene = self.server.scene
        if self.run.dim == 2:
            for name, colour in (("inner", _GREEN), ("outer", _GREY)):
                segs = np.concatenate([_segments(np.vstack([c, c[:1]])) for c in truth[name]])
                self._handles[f"/truth/{name}"] = scene.add_line_segments(
                    f"/truth/{name}", segs, colour, thickness=2.0, thickness_units="screen"
                )
        else:
            m = truth["inner"]
            self._handles["/truth/inner"] = scene.add_mesh_simple(
                "/truth/inner", m.vertices, m.faces, color=_GREEN, wireframe=True, opacity=0.3
            )
            if truth.get("outer") is not None:
                o = truth["outer"]
                self._handles["/truth/outer"] = scene.add_mesh_simple(
                    "/truth/outer", o.vertices, o.faces, color=_GREY, opacity=0.15, side="double"
                )

    # ---------------------------------------------------------------------------------------------------- drawing
    def show(self, step: int) -> None:
        """Draw the run after ``step`` (the last recorded step at or before it)."""
        from viser import uplot

        with self._lock:
            run = self.run
            k = run.nearest_step(step)
            ds = run.states[k]
            scene = self.server.scene
            size = 0.004 if run.dim == 2 else 0.006
            on = {name: bool(box.value) for name, box in self.layers.items()}
            groups = {"/cloud/seen": ((ds.task == 1) & (ds.y == 0), _GREY, "point cloud"),
                      "/cloud/free": ((ds.task == 1) & (ds.y == 1), _LIGHT_BLUE, "point cloud"),
                      "/touch/contacts": ((ds.task == 0) & (ds.y == 0), _BLACK, "touches"),
                      "/touch/free": ((ds.task == 0) & (ds.y == 1), _CYAN, "touches"),
                      "/cloud/inside": ((ds.task == 1) & (ds.y < 0), _PURPLE, "point cloud"),
                      "/touch/inside": ((ds.task == 0) & (ds.y < 0), _PURPLE, "touches")}
            for name, (mask, colour, layer) in groups.items():
                pts = _lift(ds.x[mask]) if mask.any() else np.zeros((1, 3))
                self._handles[name] = scene.add_point_cloud(
                    name,
                    pts,
                    colour,
                    point_size=size * (1.6 if "contacts" in name else 1.0),
                    point_shape="circle",
                    visible=bool(on[layer] and mask.any()),
                )
            pads = run.pad_footprints(k) if run.dim == 3 else np.zeros((0, 4, 3))
            if len(pads) or self._handle("/touch/pads") is not None:
                # each pad's outline: its four edges, the current one brighter than the earlier ones
                edges = np.stack([pads, np.roll(pads, -1, axis=1)], axis=2).reshape(-1, 2, 3)
                if not len(edges):
                    edges = np.zeros((1, 2, 3))
                colours = np.tile(np.array(_PAD_OLD, dtype=np.uint8), (len(edges), 2, 1))
                colours[-4:] = _PAD
                self._handles["/touch/pads"] = scene.add_line_segments(
                    "/touch/pads", edges, colours, thickness=2.0, thickness_units="screen",
                    visible=bool(on["touches"] and len(pads)))
            upto = (run.trajectory[run.trajectory_step <= k] if run.trajectory is not None and k > 0
                    else np.zeros((0, run.dim)))
            shown = len(upto) > 1
            self._handles["/path"] = scene.add_line_segments(
                "/path", _segments(upto if shown else np.zeros((2, run.dim))), _ORANGE, thickness=2.0,
                thickness_units="screen", visible=on["path"] and shown)
            surface, var, prior = self._estimate(k)
            self._draw_estimate(surface, var, prior, visible=on["estimate"])
            for name in ("/truth/inner", "/truth/outer"):
                handle = self._handle(name)
                if handle is not None:
                    handle.visible = on["true shapes"]
            steps, s, r = self._series
            mark = np.full(len(steps), np.nan)
            # no marker where the similarity does not apply (touch only, a step before any touch): a red dot at 0
            # read as a measured similarity of 0
            mark[run.steps.index(k)] = s[run.steps.index(k)]
            self.plot.data = (steps, s, r, mark)
            # uPlot has no NaN: a NaN in auto-ranged data makes the y range NaN and the whole chart blank (the
            # "this step" marker, and unidentified or not yet fitted steps, are NaN). Fix the y range from the
            # finite values instead; NaN points are then simply not drawn.
            finite = np.concatenate([s[np.isfinite(s)], r[np.isfinite(r)]])
            y = (min(float(finite.min()) if len(finite) else 0.0, 0.0) - 0.05,
                 max(float(finite.max()) if len(finite) else 1.0, 1.0) + 0.05)
            if y != self._y_range:
                self._y_range = y
                self.plot.scales = {"x": uplot.Scale(time=False), "y": uplot.Scale(auto=False, range=y)}
            p = run.params.get(k, {})
            def fmt(v):
                return "n/a" if v is None or not math.isfinite(v) else f"{v:.3f}"

            h = p.get("hausdorff", math.nan)
            if run.meta.get("touch") == "patch":         # pad points are not touches: count both, by name
                touches = sum(1 for st in run.steps if st <= k and "contact" in run.params.get(st, {}))
                surface_pts = int(((ds.task == 0) & (ds.y == 0)).sum())
                inner = f"{touches} touch{'' if touches == 1 else 'es'} ({surface_pts} pad surface points)"
            else:                                        # each contact once, however often the model counts it
                inner = f"{int(ds.contact_rows().sum())} contacts"
            touch_only = run.meta.get("mode") == "tactile"
            measures = ("similarity and correlation: do not apply (touch only)" if touch_only else
                        f"similarity {fmt(p.get('similarity'))}, correlation {fmt(p.get('correlation'))}")
            self.info.content = (
                f"**{run.name}** ({run.meta.get('world', 'data')} {run.meta.get('scene', '')}, "
                f"{run.meta.get('mode', 'dataset')})  \n"
                f"step **{k}** of {run.steps[-1]}: {inner}, "
                f"{int(((ds.task == 0) & (ds.y == 1)).sum())} free-space, {int((ds.task == 1).sum())} outer points"
                + (f", {int((ds.y < 0).sum())} inside" if (ds.y < 0).any() else "") + "  \n"
                f"{measures}, Hausdorff {'n/a' if not math.isfinite(h) else f'{h * 100:.1f} cm'}"
                + self._learned_values(run, p) + self._camera_corrections(run, k)
                + self._on_body(run, k) + self._no_estimate(surface)
                + ("" if self._truth() is not None else "  \ntrue shape: not known for this run"))
        self.shown_step = k

    @staticmethod
    def _learned_values(run, p: dict) -> str:
        """The kernel's length and sigma^2 at this step, for runs that learned them (``learn`` in the header)."""
        if run.meta.get("learn", "task") == "task":
            return ""
        length, noise = p.get("length", math.nan), p.get("noise", math.nan)
        if not (math.isfinite(length) and math.isfinite(noise)):
            return ""
        return f"  \nlearned ({run.meta['learn']}): kernel length {length * 100:.1f} cm, sigma^2 {noise:.4g}"

    @staticmethod
    def _camera_corrections(run, k: int) -> str:
        """What the touches moved each camera capture by (``camera_bound``), from the step that did it on (a log), or
        for the whole dataset (``gpioius fit --camera-bound``); "" without."""
        found = run.meta.get("camera_corrections")
        at = None
        for step in run.steps:
            if step <= k and "camera_corrections" in run.params.get(step, {}):
                found, at = run.params[step]["camera_corrections"], step
        if not isinstance(found, dict):
            return ""
        from .sensors.extrinsics import misfit_text

        views = ", ".join(f"{c['size_mm']:.1f} mm {c['angle_deg']:.2f} deg" for c in found.get("captures", []))
        when = "" if at is None else f" at step {at}"
        return (f"  \ncamera captures corrected from the touches{when}: {views} "
                f"({misfit_text(found)})")

    def _no_estimate(self, surface) -> str:
        """A line saying that this step's estimate has no surface (an empty picture must not look like a bug)."""
        if surface is None or (self.run.dim == 2 and not surface):
            return ("  \n**No estimate at this step:** the inner zero level {mu_in = 0} has no surface in the view "
                    "(nothing to draw)")
        return ""

    @staticmethod
    def _on_body(run, k: int) -> str:
        """"contacts on the body" up to step ``k``, where the log knows the truth (simulated worlds), else ""."""
        on, near = [], []
        for step in run.steps:
            if step > k:
                break
            q = run.params.get(step, {})
            if math.isfinite(q.get("contact_on_body", math.nan)):
                on.append(q["contact_on_body"])
            if math.isfinite(q.get("contact_distance", math.nan)):
                near.append(abs(q["contact_distance"]) <= 0.01)
        if not near:
            return ""
        text = f"  \ncontacts within 1 cm of the body: {sum(near)} of {len(near)}"
        return text + (f", on the body itself: {int(sum(on))} of {len(on)}" if on else "")

    def _handle(self, name: str):
        return self._handles.get(name)

    def _draw_estimate(self, surface, var, prior: float, visible: bool) -> None:
        from matplotlib import colormaps

        scene = self.server.scene
        cmap = colormaps["Purples"]
        if surface is None or (self.run.dim == 2 and not surface):
            handle = self._handle("/estimate")
            if handle is not None:
                handle.visible = False
            return
        if self.run.dim == 2:
            segs, colours = [], []
            for c, v in zip(surface, var):
                segs.append(_segments(c))
                mid = 0.5 * (v[:-1] + v[1:])
                rgb = (cmap(np.clip(0.35 + 0.65 * mid / prior, 0, 1))[:, :3] * 255).astype(np.uint8)
                colours.append(np.repeat(rgb[:, None], 2, axis=1))
            self._handles["/estimate"] = scene.add_line_segments(
                "/estimate",
                np.concatenate(segs),
                np.concatenate(colours),
                thickness=4.0,
                thickness_units="screen",
                visible=visible,
            )
        else:
            mesh = surface.copy()
            mesh.visual.vertex_colors = (cmap(np.clip(0.3 + 0.7 * var / prior, 0, 1)) * 255).astype(np.uint8)
            self._handles["/estimate"] = scene.add_mesh_trimesh("/estimate", mesh, visible=visible)

    def close(self) -> None:
        """Stop the server."""
        self.server.stop()


def frame_distance(radius: float, fov: float, fill: float = 0.5) -> float:
    """Distance [m] from which a sphere of ``radius`` [m] spans ``fill`` of a perspective view's height.

    The sphere's silhouette seen from distance ``d`` has angular radius ``asin(r / d)``; it spans ``fill`` of the
    view's vertical field ``fov`` [rad] when ``tan(asin(r / d)) = fill * tan(fov / 2)``.
    """
    t = fill * math.tan(fov / 2)
    return radius * math.sqrt(1.0 + 1.0 / (t * t))


def _colour_key_html() -> str:
    """The colour key of the scene as static HTML (swatches and labels; no script)."""
    rows = "".join(f'<div style="display:flex;align-items:center;gap:4px;margin:1px 0">'
                   f'<span style="width:10px;height:10px;border-radius:50%;background:rgb{c};display:inline-block;'
                   f'flex:none"></span>{label}</div>' for label, c in COLOUR_KEY)
    rows = f'<div style="display:grid;grid-template-columns:1fr 1fr;column-gap:8px">{rows}</div>'
    bar = ('<div style="display:flex;align-items:center;gap:6px;margin:3px 0"><span style="width:48px;height:10px;'
           'background:linear-gradient(to right,#fcfbfd,#3f007d);display:inline-block;flex:none"></span>'
           'estimate (&mu;_in = 0) by its variance: white certain, purple the prior</div>')
    return f'<div style="font-size:0.8em;padding:2px 4px"><b>colour key</b>{rows}{bar}</div>'


def _browser_host(host: str) -> str:
    """How a browser on this machine reaches an interface (``localhost`` for loopback and all interfaces)."""
    if host in ("127.0.0.1", "0.0.0.0", "::", "::1", "localhost"):
        return "localhost"
    return f"[{host}]" if ":" in host else host


def port_note(asked: int, served: int) -> str | None:
    """The line that says a viewer serves on another port than the one asked for (viser takes the next free port
    when the asked one is taken), or None (the port asked for, or 0: any)."""
    if asked and served != asked:
        return f"gpioius view: port {asked} is taken; serving on port {served} instead"
    return None


def serve(source: str | os.PathLike, *, port: int = 8080, open_browser: bool = True,
          resolution: float | None = None, host: str = "127.0.0.1", allow_hosts=()) -> None:
    """Serve :class:`RunViewer` until interrupted (Ctrl-C); the address is printed once every run is loaded.

    Raises:
        ValueError: a bad port, host or resolution.
        DatasetError: no run of the source could be read.
    """
    host = check_host(host)
    viewer = RunViewer(source, host=host, port=port, resolution=resolution, progress=True, allow_hosts=allow_hosts)
    warning = public_bind_warning(host)
    if warning:
        print(warning, file=sys.stderr, flush=True)
    url = f"http://{_browser_host(host)}:{viewer.port}"
    moved = port_note(port, viewer.port)
    if moved:
        print(moved, file=sys.stderr, flush=True)
    for path, why in viewer.skipped.items():
        print(f"gpioius view: left out {path}: {why}", file=sys.stderr, flush=True)
    print(f"gpioius view: {len(viewer.files)} run(s) at {url} (Ctrl-C to stop)", flush=True)
    if open_browser:
        webbrowser.open(url)
    try:
        while True:
            time.sleep(1.0)
    finally:
        viewer.close()
