"""Shared test helpers: commands run in this process or a fresh one, the shared smoke training run, free ports, a tiny
environment, and the tiers.

Tiers: ``python -m pytest -m "not slow"`` is the quick tier for contributors; tests marked ``slow`` train, start Ray
clusters or live ROS 2 nodes, or open the browser. ``python -m pytest`` runs all. The quick tier trains nothing and
starts no Ray cluster and no ROS 2 node: a test that asks for a fixture that does (:data:`HEAVY_FIXTURES`) without the
``slow`` mark stops the collection, naming it, and a quick test whose code reaches the training loop fails there
(:func:`_no_training_in_the_quick_tier`).

The budget (docs/contributing.md): CI within 45 minutes, the quick tier within 10; a new slow test says in its
docstring or its mark's comment why it must be slow. ``python -m pytest --durations=30`` shows what a change costs.
"""

from __future__ import annotations

import contextlib
import io
import os
import random
import runpy
import signal
import subprocess
import sys
import traceback
import warnings
from collections.abc import Callable
from pathlib import Path

import pytest

from atrv_warp.integrations.viewer import free_port as _free_port
from atrv_warp.integrations.viewer import port_open

ROOT = Path(__file__).resolve().parent.parent
SMOKE = "smoke"  # the preset shipped inside the package

HEAVY_FIXTURES = {"smoke_run": "trains", "ros_env": "starts ROS 2 nodes",
                  "no_ray_before": "guards a test that starts a Ray cluster"}
"""Fixtures a test may use only when it is marked ``slow`` (name -> what it does)."""


def _run(cmd: list[str], *, check: bool = True, env: dict | None = None,
         timeout: float | None = None) -> subprocess.CompletedProcess:
    proc = subprocess.run(cmd, capture_output=True, text=True, cwd=ROOT, env=env, timeout=timeout, check=False)
    if check and proc.returncode != 0:
        raise AssertionError(f"{cmd} failed ({proc.returncode}):\n{proc.stdout[-3000:]}\n{proc.stderr[-3000:]}")
    return proc


@contextlib.contextmanager
def _process_state_kept():
    """What a command may change in its process and a fresh interpreter would have thrown away, put back after it:
    the environment, the working folder, ``sys.argv`` and ``sys.path``, torch's thread count, the CPU affinity (a
    trainer pins itself), SIGINT/SIGTERM handlers, the warning filters and torch's, numpy's and Python's global random
    states."""
    import numpy as np
    import torch

    environ, cwd, argv, path = dict(os.environ), os.getcwd(), list(sys.argv), list(sys.path)
    threads, torch_rng, np_rng, py_rng = torch.get_num_threads(), torch.get_rng_state(), np.random.get_state(), \
        random.getstate()
    cores = os.sched_getaffinity(0) if hasattr(os, "sched_getaffinity") else None
    handlers = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        with warnings.catch_warnings():
            # runpy's note when the module was imported before (an earlier test did), harmless here
            warnings.filterwarnings("ignore", "'.*' found in sys.modules after import of package", RuntimeWarning)
            yield
    finally:
        os.environ.clear()
        os.environ.update(environ)
        os.chdir(cwd)
        sys.argv[:], sys.path[:] = argv, path
        torch.set_num_threads(threads)
        torch.set_rng_state(torch_rng)
        np.random.set_state(np_rng)
        random.setstate(py_rng)
        if cores is not None:
            os.sched_setaffinity(0, cores)
        for s, handler in handlers.items():
            signal.signal(s, handler)


def run_in_process(module: str, *args: str) -> subprocess.CompletedProcess:
    """``python -m module args`` in this process, in the repository root, as the interpreter would run it: its
    output captured, its exit status from ``SystemExit`` (a message exits 1 on stderr), an uncaught exception's
    traceback on stderr with status 1; what it changed in the process put back (:func:`_process_state_kept`).
    Saves what a fresh interpreter spends importing torch, Warp and Newton and loading the kernels (seconds a
    command: tests/test_train.py took 108 s of CI here, from 292 s, ci_time.json)."""
    out, err = io.StringIO(), io.StringIO()
    code = 0
    with _process_state_kept(), contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        os.chdir(ROOT)
        sys.argv[:] = [module, *args]
        try:
            runpy.run_module(module, run_name="__main__", alter_sys=True)
        except SystemExit as done:
            if isinstance(done.code, int) or done.code is None:
                code = done.code or 0
            else:
                print(done.code, file=sys.stderr)
                code = 1
        except KeyboardInterrupt:
            raise
        except Exception:  # noqa: BLE001 - as the interpreter does: the traceback, status 1
            traceback.print_exc()
            code = 1
    return subprocess.CompletedProcess([sys.executable, "-m", module, *args], code, out.getvalue(), err.getvalue())


@pytest.fixture(scope="session")
def run_command() -> Callable[..., subprocess.CompletedProcess]:
    """``run_command(cmd, check=True, env=None, timeout=None)``: run ``cmd`` in the repository root,
    capture its text output, and (``check``) fail with its last output unless it exits 0."""
    return _run


@pytest.fixture(scope="session")
def run_module() -> Callable[..., subprocess.CompletedProcess]:
    """``run_module("atrv_warp.evaluate", *args, check=True, env=None, timeout=None, fresh=False)``: ``python -m``
    that module, (``check``) failing with its last output unless it exits 0: in this process
    (:func:`run_in_process`), or in a fresh interpreter where the test passes ``env`` or ``fresh=True`` (a command
    that must start from nothing: one killed from outside, one whose imports are the point)."""

    def run_module(*args: str, check: bool = True, env: dict | None = None, timeout: float | None = None,
                   fresh: bool = False):
        if fresh or env is not None:
            return _run([sys.executable, "-m", *args], check=check, env=env, timeout=timeout)
        proc = run_in_process(*args)
        if check and proc.returncode != 0:
            raise AssertionError(f"python -m {' '.join(args)} failed ({proc.returncode}):\n{proc.stdout[-3000:]}\n"
                                 f"{proc.stderr[-3000:]}")
        return proc

    return run_module


@pytest.fixture(scope="session")
def smoke_run(tmp_path_factory) -> tuple[Path, str]:
    """One smoke training run (``--config smoke``, with progress) shared by every test that reads a trained run, in a
    fresh interpreter: ``(its run folder, its stdout + stderr)``. Tests copy what they change."""
    out = tmp_path_factory.mktemp("runs")
    proc = _run([sys.executable, "-m", "atrv_warp.train", "--config", SMOKE, f"out_dir={out}",
                 "--logging.progress", "True"])
    return out / "smoke", proc.stdout + proc.stderr


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
    from atrv_warp import RoverEnv

    env = RoverEnv(4, seed=0)
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


# --- the tiers ---------------------------------------------------------------------------------------------------

def heavy_without_slow(items) -> list[str]:
    """The collected tests that use a :data:`HEAVY_FIXTURES` fixture without the ``slow`` mark, one line each."""
    return [f"{item.nodeid} uses the fixture {name!r} ({why}) but is not marked slow"
            for item in items if item.get_closest_marker("slow") is None
            for name, why in HEAVY_FIXTURES.items() if name in getattr(item, "fixturenames", ())]


def pytest_collection_modifyitems(config, items):
    wrong = heavy_without_slow(items)
    if wrong:
        raise pytest.UsageError("the quick tier trains nothing and starts no node or cluster:\n  " + "\n  ".join(wrong))


class TrainingInTheQuickTier(AssertionError):
    """A test not marked ``slow`` reached the training loop."""


@pytest.fixture(autouse=True)
def _no_training_in_the_quick_tier(request, monkeypatch):
    """In a test not marked ``slow``, the training loop (``TrainLoop.run``, in this process) raises
    :class:`TrainingInTheQuickTier` instead of training; a refusal before any work still runs as it would."""
    if request.node.get_closest_marker("slow") is not None:
        yield
        return
    from atrv_warp.rl.loop import TrainLoop

    def refuse(self, *args, **kwargs):
        raise TrainingInTheQuickTier(f"{request.node.nodeid} trains but is not marked slow: mark it "
                                     "@pytest.mark.slow (and say why it must train), or use the shared smoke_run")

    monkeypatch.setattr(TrainLoop, "run", refuse)
    yield


@pytest.fixture(autouse=True, scope="module")
def _adjoints_off_after_a_file_that_differentiates():
    """A differentiable simulator compiles Warp's kernels with their adjoints from then on, in its whole process
    (:func:`atrv_warp.runtime.enable_gradients`); after the test file that built one (its module-scoped fixtures may
    hold one), this puts the process back as the package's import leaves it (every module, and what compiles next,
    without adjoints), so that a later file's test in the same worker compiles what its own command would. Left on,
    the tests after the gradient tests paid the adjoints' compile: the eight-wheel friction solve took 69 s instead of
    7 (a cold kernel cache, the quick tier on two workers)."""
    yield
    wp = sys.modules.get("warp")
    if wp is None or "atrv_warp.runtime" not in sys.modules or not wp.config.enable_backward:
        return  # as the package's import leaves it (runtime.configure: no adjoints)
    from warp._src.context import user_modules

    wp.config.enable_backward = False
    for module in list(user_modules.values()):
        if module.options.get("enable_backward"):
            wp.set_module_options({"enable_backward": False}, module)

