"""What the benchmark scripts share: pinning to one core, and writing the results file with its
provenance.

The scripts run as ``python benchmarks/<name>.py``, so this folder is on ``sys.path`` and they
import it as ``_common``. Each script defines ``VERSION``, an integer bumped by hand when its
method changes (what it measures or how), and passes it to :func:`write_results`; a refactor that
measures the same thing leaves it alone.
"""

from __future__ import annotations

import datetime
import hashlib
import json
import os
import shlex
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def pin_to_one_core() -> None:
    """Run this process (and the threads it starts) on the lowest core it may use, where the OS
    allows it: one core for every measurement, so figures compare within a run."""
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})


def labelled(spec: str) -> tuple[str, str]:
    """``(label, policy)`` of a command line's ``LABEL=POLICY``, or of ``POLICY`` (labelled by itself)."""
    label, _, policy = spec.rpartition("=")
    return (label or policy), policy


def _git(*args: str) -> str:
    try:
        return subprocess.run(["git", *args], cwd=ROOT, capture_output=True, text=True, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return ""


def file_sha256(path: str | Path) -> str:
    """The sha256 of a file's bytes (a policy's ``.pt``)."""
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def _relative(path: str | Path) -> str:
    p = Path(path).resolve()
    return str(p.relative_to(ROOT)) if p.is_relative_to(ROOT) else str(p)


def provenance(version: int, *, script: str | Path | None = None, dynamics: bool = True, task: bool = False,
               policies: tuple[str | Path, ...] = (), driver: bool = False, robots: tuple[str, ...] = ()) -> dict:
    """What a results file's figures depend on, recorded beside them (``docs/hooks.py`` checks it).

    Args:
        version: the script's ``VERSION``.
        script: the benchmark script; by default the one being run (``__main__``).
        dynamics: whether the figures depend on the simulator's dynamics; if so, the current
            :func:`atrv_warp.sim.checks.dynamics_fingerprint` is recorded.
        task: whether they depend on the tasks (observations, rewards, resets, randomization); if so, the
            current :func:`atrv_warp.task.evaluation.task_fingerprint` is recorded.
        policies: the policy files the script ran; each one's sha256 is recorded.
        driver: whether they went through the base's motor driver (``/cmd_vel``, velocity actions); if so, the
            current :func:`atrv_warp.sim.checks.driver_fingerprint` is recorded.
        robots: the robots the figures are of (names or robot files); each one's file and URDF sha256 is recorded.

    Returns:
        ``date`` (UTC), ``commit`` and ``dirty`` (uncommitted changes to tracked files), ``script``,
        ``script_version``, ``command`` (the command line that ran, when the script is the one being run),
        and ``dynamics``, ``driver``, ``task``, ``policies`` and ``robots`` where they apply.
    """
    main = getattr(sys.modules["__main__"], "__file__", None) or sys.argv[0]
    script = script or main
    record = {"date": datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%dT%H:%M:%SZ"),
              "commit": _git("rev-parse", "HEAD"),
              "dirty": bool(_git("status", "--porcelain", "--untracked-files=no")),
              "script": _relative(script), "script_version": int(version)}
    if Path(script).resolve() == Path(main).resolve():  # the command that wrote it, to run again
        record["command"] = shlex.join(["python", _relative(script), *sys.argv[1:]])
    if dynamics:
        from atrv_warp.sim.checks import dynamics_fingerprint

        record["dynamics"] = dynamics_fingerprint()
    if driver:
        from atrv_warp.sim.checks import driver_fingerprint

        record["driver"] = driver_fingerprint()
    if task:
        from atrv_warp.task.evaluation import task_fingerprint

        record["task"] = task_fingerprint()
    if policies:
        record["policies"] = {_relative(p): file_sha256(p) for p in policies}
    if robots:
        from atrv_warp.core.robot import load_robot

        files = [f for r in robots for f in (load_robot(r).path, load_robot(r).urdf)]
        record["robots"] = {_relative(f): file_sha256(f) for f in files}
    return record


def write_results(path: str | Path, result: dict, *, version: int, dynamics: bool = True, task: bool = False,
                  policies: tuple[str | Path, ...] = (), driver: bool = False, robots: tuple[str, ...] = ()) -> Path:
    """Write ``result`` as indented JSON to ``path``, creating its folder, with its
    :func:`provenance` under the key ``"provenance"``; returns the path.

    Args:
        path: the results file.
        result: the figures.
        version: the calling script's ``VERSION``.
        dynamics: whether the figures depend on the simulator's dynamics.
        task: whether they depend on the tasks (an environment ran).
        policies: the policy files the script ran.
        driver: whether they went through the base's motor driver.
        robots: the robots they are of (their files' and URDFs' sha256 are recorded).
    """
    result = {**result, "provenance": provenance(version, dynamics=dynamics, task=task, policies=tuple(policies),
                                                 driver=driver, robots=tuple(robots))}
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(result, indent=2) + "\n")
    return out
