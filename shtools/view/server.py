"""The viewer's local HTTP server: the page, the bake's arrays, a clean stop.

Standard library only (:mod:`http.server`), bound to 127.0.0.1: the page
(``static/``, plain WebGL 2, nothing fetched from elsewhere) works offline.

Routes (all GET):

=========================================  ============================================
``/``, ``/viewer.js``                      the page
``/api/bake.json``                         :meth:`BakeView.summary`
``/api/faces.bin``                         uint32 ``(F, 3)`` triangles
``/api/positions.bin?frame=T``             float32 ``(V, 3)``
``/api/colors.bin?frame=T&quantity=Q&exposure=E``  uint8 ``(V, 3)`` sRGB
``/api/spheres.bin?frame=T``               float32 ``(N, 4)`` centre and radius
=========================================  ============================================
"""

from __future__ import annotations

import contextlib
import errno
import json
import signal
import threading
from http import HTTPStatus
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from importlib import resources
from urllib.parse import parse_qs, urlparse

from shtools.errors import InputError
from shtools.view.data import BakeView

HOST = "127.0.0.1"
#: the page's files: name -> content type
STATIC = {"index.html": "text/html; charset=utf-8",
          "viewer.js": "text/javascript; charset=utf-8"}


def _static(name: str) -> bytes:
    return resources.files("shtools.view").joinpath("static", name).read_bytes()


class _Handler(BaseHTTPRequestHandler):
    """One request; the view is the server's (``server.view``)."""

    server_version = "shtools-view"

    def log_message(self, format, *args):
        """No request log: it would drown the URL line; errors answer the page."""

    def do_GET(self):
        url = urlparse(self.path)
        query = {k: v[-1] for k, v in parse_qs(url.query).items()}
        view: BakeView = self.server.view
        route = url.path.lstrip("/") or "index.html"
        try:
            if route in STATIC:
                self._send(_static(route), STATIC[route])
            elif route == "api/bake.json":
                self._send(json.dumps(view.summary()).encode(), "application/json")
            elif route == "api/faces.bin":
                self._send(view.faces())
            elif route == "api/positions.bin":
                self._send(view.positions(query.get("frame", 0)))
            elif route == "api/colors.bin":
                self._send(view.colors(query.get("frame", 0),
                                       query.get("quantity", "radiance"),
                                       float(query.get("exposure", 0.0))))
            elif route == "api/spheres.bin":
                self._send(view.sphere_bytes(query.get("frame", 0)))
            else:
                self._send(b"not found", "text/plain", HTTPStatus.NOT_FOUND)
        except (InputError, ValueError) as exc:
            self._send(str(exc).encode(), "text/plain", HTTPStatus.BAD_REQUEST)
        except (BrokenPipeError, ConnectionResetError):
            return  # the page went away mid-answer (a reload): nobody to answer

    def _send(self, body: bytes, content_type="application/octet-stream",
              status=HTTPStatus.OK):
        self.send_response(status)
        self.send_header("Content-Type", content_type)
        self.send_header("Content-Length", str(len(body)))
        self.send_header("Cache-Control", "no-store")
        self.end_headers()
        self.wfile.write(body)


class ViewerServer(ThreadingHTTPServer):
    """The viewer's HTTP server on 127.0.0.1 (``port`` 0: a free port).

    Request threads are daemons, so stopping never waits for a browser's open
    connection.

    Raises
    ------
    InputError
        The port is in use or cannot be bound.
    """

    daemon_threads = True
    allow_reuse_address = False  # a port in use is an error, not shared

    def __init__(self, view: BakeView, port: int = 0):
        self.view = view
        try:
            super().__init__((HOST, int(port)), _Handler)
        except OSError as exc:
            if exc.errno == errno.EADDRINUSE:
                raise InputError(f"--port {port} is in use on {HOST}; pick another port or "
                                 "leave --port out for a free one") from None
            raise InputError(f"--port {port}: cannot listen on {HOST} ({exc.strerror}); "
                             "pick another port") from None

    @property
    def url(self) -> str:
        return f"http://{HOST}:{self.server_address[1]}/"


def serve(view: BakeView, port: int = 0, *, on_ready=None) -> None:
    """Serve ``view`` until Ctrl-C or SIGTERM, then close the socket and return.

    Parameters
    ----------
    view : BakeView
    port : int
        0 picks a free port.
    on_ready : callable, optional
        Called with the URL once the server listens (print it, open a browser).
    """
    with ViewerServer(view, port) as server:
        stop = threading.Event()

        def _terminate(signum, frame):
            stop.set()

        previous = None
        if threading.current_thread() is threading.main_thread():
            previous = signal.signal(signal.SIGTERM, _terminate)
        thread = threading.Thread(target=server.serve_forever, kwargs={"poll_interval": 0.2},
                                  name="shtools-view", daemon=True)
        thread.start()
        try:
            # Ctrl-C (SIGTERM sets stop) from the moment the URL is out: a signal sent
            # as soon as a client has its first page may come before stop.wait()
            with contextlib.suppress(KeyboardInterrupt):
                if on_ready is not None:
                    on_ready(server.url)
                stop.wait()
        finally:
            server.shutdown()
            thread.join()
            if previous is not None:
                signal.signal(signal.SIGTERM, previous)
