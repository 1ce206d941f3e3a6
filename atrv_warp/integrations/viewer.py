"""Rerun's web viewer as a process of its own: :class:`ServedViewer` starts ``rerun --serve-web``
bound to 127.0.0.1, waits until it answers, and stops its whole process group.

A recording streams to it with :meth:`ServedViewer.connect`; :mod:`.browser` opens it in headless
Chromium.
"""

from __future__ import annotations

import os
import shutil
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path
from typing import Self

import rerun as rr

__all__ = ["ServedViewer", "free_port", "port_open"]


def free_port() -> int:
    """A TCP port on 127.0.0.1 that nothing listens on now."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def port_open(port: int) -> bool:
    """Something accepts connections on 127.0.0.1:``port``."""
    with socket.socket() as s:
        return s.connect_ex(("127.0.0.1", port)) == 0


class ServedViewer:
    """Rerun's web viewer and gRPC proxy, bound to 127.0.0.1 only, as a context manager.

    ``start()`` launches ``rerun --serve-web`` in its own process session and waits until the
    gRPC proxy accepts connections and the web page answers; ``stop()`` signals the whole process
    group (a launcher may exit before the viewer binary it started) and waits until both ports
    are free. The SDK's own ``serve_grpc`` binds every interface, so it is not used.

    Example::

        with ServedViewer() as viewer:
            viewer.connect(rec)            # a rr.RecordingStream
            print(viewer.url)              # open in a browser
    """

    def __init__(self, *, grpc_port: int | None = None, web_port: int | None = None, timeout_s: float = 20.0):
        self.grpc_port = grpc_port or free_port()
        self.web_port = web_port or free_port()
        self.timeout_s = timeout_s
        self.process: subprocess.Popen | None = None

    @property
    def grpc_url(self) -> str:
        """The proxy a recording streams to, and the viewer reads from."""
        return f"rerun+http://127.0.0.1:{self.grpc_port}/proxy"

    @property
    def url(self) -> str:
        """The web page to open: the viewer, pointed at the proxy."""
        return f"http://127.0.0.1:{self.web_port}/?url={self.grpc_url.replace('+', '%2B')}"

    def start(self) -> Self:
        # the venv's own script first: a venv's python run without activating the venv has no bin/ on PATH
        exe = shutil.which("rerun", path=str(Path(sys.executable).parent)) or shutil.which("rerun")
        if exe is None:
            raise RuntimeError(f"the 'rerun' command (installed with rerun-sdk) is neither beside {sys.executable} "
                               "nor on PATH")
        for port in (self.grpc_port, self.web_port):
            if port_open(port):
                raise RuntimeError(f"port {port} on 127.0.0.1 is already in use")
        self.process = subprocess.Popen(
            [exe, "--serve-web", "--bind", "127.0.0.1", "--port", str(self.grpc_port),
             "--web-viewer-port", str(self.web_port)],
            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
        deadline = time.monotonic() + self.timeout_s
        while not self.healthy():
            if self.process.poll() is not None:
                code = self.process.returncode
                self.stop()
                raise RuntimeError(f"rerun viewer server exited with code {code}")
            if time.monotonic() > deadline:
                self.stop()
                raise RuntimeError(f"rerun viewer server did not answer within {self.timeout_s:g} s")
            time.sleep(0.1)
        return self

    def healthy(self) -> bool:
        """The proxy accepts connections and the web page answers HTTP 200."""
        import urllib.request

        if not (port_open(self.grpc_port) and port_open(self.web_port)):
            return False
        try:
            with urllib.request.urlopen(f"http://127.0.0.1:{self.web_port}/", timeout=2.0) as resp:
                return resp.status == 200
        except OSError:
            return False

    def connect(self, rec: rr.RecordingStream) -> None:
        """Stream ``rec`` to the proxy (the viewer shows it live)."""
        rec.connect_grpc(self.grpc_url)

    def stop(self) -> None:
        """Stop the server's whole process group and wait until its ports are free (idempotent)."""
        proc, self.process = self.process, None
        if proc is None:
            return
        for sig, wait in ((signal.SIGTERM, 5.0), (signal.SIGKILL, None)):
            try:
                os.killpg(proc.pid, sig)
            except ProcessLookupError:
                break
            if wait is not None:
                try:
                    proc.wait(timeout=wait)
                except subprocess.TimeoutExpired:
                    pass
        proc.wait()
        deadline = time.monotonic() + 10.0
        while (port_open(self.grpc_port) or port_open(self.web_port)) and time.monotonic() < deadline:
            time.sleep(0.1)

    def __enter__(self) -> Self:
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()
