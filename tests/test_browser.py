"""The served Rerun web viewer, opened in a real headless Chromium (marker ``browser``).

Runs where Chromium is installed (Debian's ``chromium``; ``.ci/run`` installs it and sets
``ATRV_WARP_REQUIRE_BROWSER=1`` so that a missing browser fails instead of skipping). Playwright
drives the browser through its own executable path: no browser download.

What it proves: the page loads from our localhost server, the viewer's WebAssembly starts, it
connects to our gRPC proxy and reads the recording from it (gRPC-web requests answered 200), the
console shows no panic, a screenshot is taken; and after the viewer stops, no port is left bound.
"""

from __future__ import annotations

import os

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
    from atrv_warp.integrations.browser import capture_viewer
    from atrv_warp.integrations.recorder import RerunRecorder
    from atrv_warp.task.baseline import scripted_policy
    from atrv_warp.task.evaluation import evaluate

    env = ATRVjrEnv(2)
    recorder = RerunRecorder(env.sim, serve=True, worlds=[0, 1])
    viewer = recorder.viewer
    shot = tmp_path / "viewer.png"
    try:
        evaluate(scripted_policy(), num_episodes=2, env=env, on_step=recorder.env_hook())
        recorder.rec.flush()
        report = capture_viewer(viewer, shot)
    finally:
        recorder.close()
    assert report.status == 200
    assert report.grpc_responses, f"the viewer never called the gRPC proxy; console: {report.console[-10:]}"
    assert all(status == 200 for _, status in report.grpc_responses), report.grpc_responses
    assert not [line for line in report.console if "panicked" in line], report.console
    assert not report.errors, report.errors
    # a drawn viewer (panels, plots, the 3D arena), not a blank or error page: thousands of colours
    colours = Image.open(shot).convert("RGB").getcolors(maxcolors=1 << 20)
    assert colours is not None and len(colours) > 1000, len(colours or [])
    for port in (viewer.grpc_port, viewer.web_port):
        assert port_free(port), f"port {port} still bound after the viewer stopped"
    assert viewer.process is None
