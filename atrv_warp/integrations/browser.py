"""Open a served Rerun web viewer in headless Chromium: a screenshot, and what the page did.

Playwright drives the system's Chromium (Debian's ``chromium`` package; no browser download).
The viewer renders through SwiftShader, Chromium's software rasteriser, so this works on a
machine without a GPU. Needs the ``browser`` extra (``pip install -e '.[browser]'``).

Used by ``tests/test_browser.py`` and ``docs/make_pictures.py --viewer``.
"""

from __future__ import annotations

import shutil
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from atrv_warp.integrations.viewer import ServedViewer

__all__ = ["CHROMIUM_ARGS", "PageReport", "capture_viewer", "find_chromium"]

CHROMIUM_ARGS = (
    "--no-sandbox", "--disable-dev-shm-usage", "--no-first-run", "--disable-background-networking",
    "--disable-component-update", "--disable-sync", "--enable-unsafe-swiftshader", "--use-angle=swiftshader",
    "--ignore-gpu-blocklist",
)
"""Headless flags: no sandbox (root in a container), no background traffic (a closed network),
WebGL through SwiftShader."""


def find_chromium() -> str | None:
    """Path of the system's Chromium, or ``None``."""
    return shutil.which("chromium") or shutil.which("chromium-browser")


@dataclass
class PageReport:
    """What happened while the viewer page was open."""

    status: int
    """HTTP status of the page itself."""
    grpc_responses: list[tuple[str, int]] = field(default_factory=list)
    """(url, status) of every request the viewer made to the gRPC proxy."""
    console: list[str] = field(default_factory=list)
    """``type: text`` of every console message."""
    errors: list[str] = field(default_factory=list)
    """Uncaught page errors."""


def capture_viewer(viewer: ServedViewer, screenshot: str | Path, *, chromium: str | None = None,
                   size: tuple[int, int] = (1280, 800), settle_s: float = 5.0, timeout_s: float = 60.0,
                   ready: Callable[[bytes], bool] | None = None) -> PageReport:
    """Open ``viewer.url`` in headless Chromium, wait until the viewer has called its gRPC proxy and
    drawn for ``settle_s``, save a PNG screenshot, and report what the page did.

    ``ready``: a test of a screenshot (PNG bytes); the page is photographed every second until it
    passes or ``timeout_s`` more have gone by (a loaded machine streams the recording in slowly), and
    the last one is saved."""
    from playwright.sync_api import sync_playwright

    chromium = chromium or find_chromium()
    if chromium is None:
        raise RuntimeError("Chromium is not installed (Debian: apt-get install chromium)")
    with sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=chromium, headless=True, args=list(CHROMIUM_ARGS))
        try:
            page = browser.new_page(viewport={"width": size[0], "height": size[1]})
            report = PageReport(status=0)
            page.on("console", lambda m: report.console.append(f"{m.type}: {m.text}"))
            page.on("pageerror", lambda e: report.errors.append(str(e)))
            page.on("response", lambda r: report.grpc_responses.append((r.url, r.status))
                    if f":{viewer.grpc_port}/" in r.url else None)
            response = page.goto(viewer.url, wait_until="load", timeout=timeout_s * 1000)
            report.status = response.status if response is not None else 0
            page.wait_for_selector("canvas", timeout=timeout_s * 1000)  # the WebAssembly viewer is up
            deadline = time.monotonic() + timeout_s
            while not report.grpc_responses and time.monotonic() < deadline:
                page.wait_for_timeout(500)
            page.wait_for_timeout(settle_s * 1000)
            shot = page.screenshot()
            deadline = time.monotonic() + timeout_s
            while ready is not None and not ready(shot) and time.monotonic() < deadline:
                page.wait_for_timeout(1000)
                shot = page.screenshot()
            Path(screenshot).write_bytes(shot)
        finally:
            browser.close()
    return report
