"""The served Rerun web viewer, opened in a real headless Chromium (marker ``browser``).

Runs where Chromium is installed (Debian's ``chromium``; ``.ci/run`` installs it and sets
``ATRV_WARP_REQUIRE_BROWSER=1`` so that a missing browser fails instead of skipping). Playwright
drives the browser through its own executable path: no browser download.

What it proves: the page loads from our localhost server, the viewer's WebAssembly starts, it
connects to our gRPC proxy and reads the recording from it (gRPC-web requests answered 200), the
console shows no panic, a screenshot is taken; and after the viewer stops, no port is left bound.
The layout the viewer got is read back from the same recording's file (the canvas is not in the
DOM): its largest view is the 3D view, and the screenshot's region of that view is drawn.
"""

from __future__ import annotations

import io
import os

import numpy as np
import pytest

from atrv_warp.integrations.browser import find_chromium

pytestmark = [pytest.mark.browser, pytest.mark.slow]


def _require_browser():
    missing = [] if find_chromium() else ["Chromium (apt-get install chromium)"]
    try:
        import playwright.sync_api  # noqa: F401
    except ImportError:
        missing.append("playwright (pip install -e '.[test]')")
    if missing:
        if os.environ.get("ATRV_WARP_REQUIRE_BROWSER") == "1":
            pytest.fail(f"required here (ATRV_WARP_REQUIRE_BROWSER=1) but missing: {missing}")
        pytest.skip(f"missing: {missing}")


def test_viewer_loads_in_chromium_and_reads_the_recording(tmp_path, port_free):
    _require_browser()
    from PIL import Image

    from atrv_warp import ATRVjrEnv
    from atrv_warp.integrations.blueprint import view_shares
    from atrv_warp.integrations.browser import capture_viewer
    from atrv_warp.integrations.recorder import RerunRecorder
    from atrv_warp.task.baseline import scripted_policy
    from atrv_warp.task.evaluation import evaluate

    env = ATRVjrEnv(2, task="nav")
    recording = tmp_path / "served.rrd"  # the same rows go to the file and to the served viewer
    recorder = RerunRecorder(env.sim, serve=True, worlds=[0, 1], path=recording)
    viewer = recorder.viewer
    shot = tmp_path / "viewer.png"
    try:
        evaluate(scripted_policy(), num_episodes=2, env=env, on_step=recorder.env_hook())
        recorder.rec.flush()
        report = capture_viewer(viewer, shot, ready=lambda png: _scene_drawn(Image.open(io.BytesIO(png)))[0])
    finally:
        recorder.close()
    assert report.status == 200
    assert report.grpc_responses, f"the viewer never called the gRPC proxy; console: {report.console[-10:]}"
    assert all(status == 200 for _, status in report.grpc_responses), report.grpc_responses
    assert not [line for line in report.console if "panicked" in line], report.console
    assert not report.errors, report.errors
    # a drawn viewer (panels, plots, the 3D arena), not a blank or error page: thousands of colours
    image = Image.open(shot).convert("RGB")
    colours = image.getcolors(maxcolors=1 << 20)
    assert colours is not None and len(colours) > 1000, len(colours or [])
    # the layout: the 3D view is the largest, on the left (1 - PLOTS_SHARE of the width)
    views = view_shares(recording)
    assert views[0].kind == "3D" and all(v.share < views[0].share for v in views[1:]), views
    drawn, why = _scene_drawn(image)
    assert drawn, why
    for port in (viewer.grpc_port, viewer.web_port):
        assert port_free(port), f"port {port} still bound after the viewer stopped"
    assert viewer.process is None


def _scene_drawn(image) -> tuple[bool, str]:
    """The screenshot's 3D region (the left 1 - PLOTS_SHARE below the top bar, above the time panel) is
    drawn: terrain, walls and obstacles in over a thousand colours cover a good part of it (an empty
    view, or one with the static walls only, is mostly one background colour)."""
    from atrv_warp.integrations.blueprint import PLOTS_SHARE

    width, height = image.size
    region = image.convert("RGB").crop((10, 80, int(width * (1 - PLOTS_SHARE)) - 10, height - 80))
    pixels = np.asarray(region).reshape(-1, 3)
    background = np.bincount(np.ravel_multi_index(pixels.T, (256, 256, 256))).max() / len(pixels)
    colours = len(region.getcolors(maxcolors=1 << 20) or [])
    return background < 0.85 and colours > 1000, f"the 3D view is {background:.0%} one colour, {colours} colours"
