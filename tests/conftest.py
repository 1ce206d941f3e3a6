"""Shared test helpers: subprocesses in the repository root, free ports, a tiny environment.

Tiers: ``python -m pytest -m "not slow"`` is the quick tier for contributors; tests marked ``slow``
train, start Ray clusters or live ROS 2 nodes, or open the browser. ``python -m pytest`` runs all.
"""

from __future__ import annotations

import os
import random
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

import pytest

from atrv_warp.integrations.viewer import free_port as _free_port
from atrv_warp.integrations.viewer import port_open

ROOT = Path(__file__).resolve().parent.parent


def _run(cmd: list[str], *, check: bool = True, env: dict | None = None,
         timeout: float | None = None) -> subprocess.CompletedProcess:
    proc = subprocess.run(cmd, capture_output=True, text=True, cwd=ROOT, env=env, timeout=timeout, check=False)
    if check and proc.returncode != 0:
        raise AssertionError(f"{cmd} failed ({proc.returncode}):\n{proc.stdout[-3000:]}\n{proc.stderr[-3000:]}")
    return proc


@pytest.fixture(scope="session")
def run_command() -> Callable[..., subprocess.CompletedProcess]:
    """``run_command(cmd, check=True, env=None, timeout=None)``: run ``cmd`` in the repository root,
    capture its text output, and (``check``) fail with its last output unless it exits 0."""
    return _run


@pytest.fixture(scope="session")
def run_module() -> Callable[..., subprocess.CompletedProcess]:
    """``run_module("atrv_warp.train", *args, check=True)``: ``python -m`` with this interpreter."""

    def run_module(*args: str, check: bool = True, env: dict | None = None, timeout: float | None = None):
        return _run([sys.executable, "-m", *args], check=check, env=env, timeout=timeout)

    return run_module


@pytest.fixture(scope="session")
def free_port() -> Callable[[], int]:
    """``free_port()``: a TCP port on 127.0.0.1 nothing listens on now."""
    return _free_port


@pytest.fixture(scope="session")
def port_free() -> Callable[[int], bool]:
    """``port_free(port)``: nothing accepts connections on 127.0.0.1:``port``."""
    return lambda port: not port_open(port)


@pytest.fixture
def tiny_env():
    """A four-world reference-task environment, seeded 0, reset."""
    from atrv_warp import ATRVjrEnv

    env = ATRVjrEnv(4, seed=0)
    env.reset()
    return env


@pytest.fixture(scope="module")
def ros_env():
    """rclpy initialised for one test module on a ROS domain of its own, discovery kept to this machine; yields the
    environment a child process (a node under test) should run with, and restores the variables afterwards."""
    rclpy = pytest.importorskip("rclpy", reason="ROS 2 extra not installed: pip install -e '.[ros]'")
    env = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST", ROS_DOMAIN_ID=str(random.randint(1, 100)),
               PYTHONUNBUFFERED="1")
    old = {k: os.environ.get(k) for k in ("ROS_AUTOMATIC_DISCOVERY_RANGE", "ROS_DOMAIN_ID")}
    os.environ.update({k: env[k] for k in old})
    rclpy.init()
    yield env
    rclpy.try_shutdown()
    for k, v in old.items():
        if v is None:
            os.environ.pop(k, None)
        else:
            os.environ[k] = v
