"""What the benchmark scripts share: pinning to one core, a timing loop, writing a results file or a figure (PNG)
with its provenance, and reading results files back to draw the docs' tables.

The scripts live in topic folders (``perf/``, ``physics/``, ``robots/``, ``calibration/``, ``transfer/``,
``training/``) of the ``benchmarks`` package and run from the repository's root as modules:
``python -m benchmarks.<topic>.<name>`` (no script edits ``sys.path``; one imports another by its module name). Each
script defines ``VERSION``, an integer bumped by hand when its method changes (what it measures or how), and passes
it to :func:`write_results` or :func:`save_figure`; a refactor that measures the same thing leaves it alone.

A script owns its figures: a module-level ``TABLES = {"NAME": function}`` names the tables a page draws with
``{{ results_table NAME }}`` (``docs/hooks.py`` renders ``TABLES[NAME]()``); each function takes no argument (or
only defaulted ones), reads its results files with :func:`load_results` (so the docs hook knows which files a page
cites) and returns Markdown (:func:`markdown_table`). The docs hook imports the scripts to find them, so a script's
module-level imports stay light (the standard library, numpy at most); torch, warp and ``atrv_warp`` are imported
inside the functions that run.
"""

from __future__ import annotations

import datetime
import hashlib
import json
import os
import shlex
import struct
import subprocess
import sys
import time
import zlib
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
RESULTS = ROOT / "benchmarks" / "results"
PNG_KEY = "atrv_warp:provenance"
"""The PNG ``tEXt`` chunk's keyword under which a figure keeps its provenance (:func:`save_figure`)."""


def pin_to_one_core() -> None:
    """Run this process (and the threads it starts) on the lowest core it may use, where the OS
    allows it: one core for every measurement, so figures compare within a run."""
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})


def random_step(env, gen):
    """A call that steps ``env`` (reset here, once) with uniform random actions in [-1, 1]² drawn from ``gen``,
    the worlds that end reset (``step_and_maybe_reset``): the environment's cost, for :func:`rate`."""
    import torch

    state = {"td": env.reset()}

    def step():
        td = state["td"]
        td["action"] = (torch.rand(env.num_envs, 2, generator=gen) * 2 - 1).to(env.device)
        _, state["td"] = env.step_and_maybe_reset(td)
    return step


def rate(fn, per_call: int, seconds: float, *, sync=None) -> float:
    """Items per second of ``fn`` (``per_call`` items a call): one warm-up call (compiles, graph captures,
    allocations), then calls until ``seconds`` have passed. ``sync`` (e.g. ``warp.synchronize``) runs after each call,
    so that a GPU's queued work counts where it was asked for."""
    fn()
    calls, t0 = 0, time.perf_counter()
    while True:
        fn()
        calls += 1
        if sync is not None:
            sync()
        elapsed = time.perf_counter() - t0
        if elapsed >= seconds:
            return calls * per_call / elapsed


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


def run_command(script: str | Path) -> list[str]:
    """How a benchmark script runs, from the repository's root: ``python -m benchmarks.<topic>.<name>`` for a script
    in the ``benchmarks`` package, ``python PATH`` for any other."""
    path = _relative(script)
    parts = Path(path).with_suffix("").parts
    if len(parts) == 3 and parts[0] == "benchmarks" and path.endswith(".py"):
        return ["python", "-m", ".".join(parts)]
    return ["python", path]


def provenance(version: int, *, script: str | Path | None = None, dynamics: bool = True, task: bool = False,
               policies: tuple[str | Path, ...] = (), driver: bool = False, robots: tuple[str, ...] = (),
               tasks: tuple[tuple[str, str], ...] = ()) -> dict:
    """What a results file's figures depend on, recorded beside them (``docs/hooks.py`` checks it).

    Args:
        version: the script's ``VERSION``.
        script: the benchmark script; by default the one being run (``__main__``).
        dynamics: whether the figures depend on the simulator's dynamics; if so, the current
            :func:`atrv_warp.sim.fingerprints.dynamics_fingerprint` is recorded.
        task: whether they depend on the tasks (observations, rewards, resets, randomization); if so, the
            current :func:`atrv_warp.task.fingerprints.task_fingerprint` is recorded.
        policies: the policy files the script ran; each one's sha256 is recorded.
        driver: whether they went through the base's motor driver (``/cmd_vel``, velocity actions); if so, the
            current :func:`atrv_warp.sim.fingerprints.driver_fingerprint` is recorded.
        robots: the robots the figures are of (names or robot files); each one's file and URDF sha256 is recorded.
        tasks: the (task, robot) pairs the figures are of, beyond the ``policies``' (each policy's recorded pair
            counts where ``task`` is set); each pair's current
            :func:`atrv_warp.task.fingerprints.task_robot_fingerprint` is recorded under ``'task@robot'``.

    Returns:
        ``date`` (UTC), ``commit`` and ``dirty`` (uncommitted changes to tracked files), ``script``,
        ``script_version``, ``command`` (the command line that ran, when the script is the one being run),
        and ``dynamics``, ``driver``, ``task``, ``tasks``, ``policies`` and ``robots`` where they apply.
    """
    main = getattr(sys.modules["__main__"], "__file__", None) or sys.argv[0]
    script = script or main
    record = {"date": datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%dT%H:%M:%SZ"),
              "commit": _git("rev-parse", "HEAD"),
              "dirty": bool(_git("status", "--porcelain", "--untracked-files=no")),
              "script": _relative(script), "script_version": int(version)}
    if Path(script).resolve() == Path(main).resolve():  # the command that wrote it, to run again
        record["command"] = shlex.join([*run_command(script), *sys.argv[1:]])
    if dynamics:
        from atrv_warp.sim.fingerprints import dynamics_fingerprint

        record["dynamics"] = dynamics_fingerprint()
    if driver:
        from atrv_warp.sim.fingerprints import driver_fingerprint

        record["driver"] = driver_fingerprint()
    if task:
        from atrv_warp.task.fingerprints import task_fingerprint

        record["task"] = task_fingerprint()
    pairs = task_robot_pairs(policies if task else (), tasks)
    if pairs:
        from atrv_warp.task.fingerprints import task_robot_fingerprint, task_robot_key

        record["tasks"] = {task_robot_key(t, r): task_robot_fingerprint(t, r) for t, r in pairs}
    if policies:
        record["policies"] = {_relative(p): file_sha256(p) for p in policies}
    if robots:
        from atrv_warp.core.robot import load_robot, robot_file_sha256

        for robot in map(load_robot, robots):  # a robot file's identity: its bytes less its [deploy] table
            record.setdefault("robots", {}).update({_relative(robot.path): robot_file_sha256(robot.path),
                                                    _relative(robot.urdf): file_sha256(robot.urdf)})
    return record


def task_robot_pairs(policies: tuple[str | Path, ...] = (), tasks: tuple[tuple[str, str], ...] = ()) -> list:
    """The (task, robot) pairs of ``tasks`` and of each policy file's record (what it trained on), each once, in
    order. A policy of a robot file of one's own records the robot, not its file's path: its pair is the caller's to
    give in ``tasks``, with the file's path."""
    from atrv_warp.core.robot import ROBOTS
    from atrv_warp.policy import policy_record

    pairs = list(tasks)
    for policy in policies:
        record = policy_record(policy)
        if record.robot.name in ROBOTS:
            pairs.append((record.task.name, record.robot.name))
    return list(dict.fromkeys((str(t), str(r)) for t, r in pairs))


def write_results(path: str | Path, result: dict, *, version: int, dynamics: bool = True, task: bool = False,
                  policies: tuple[str | Path, ...] = (), driver: bool = False, robots: tuple[str, ...] = (),
                  tasks: tuple[tuple[str, str], ...] = ()) -> Path:
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
        tasks: the (task, robot) pairs they are of beyond the policies' (:func:`provenance`).
    """
    result = {**result, "provenance": provenance(version, dynamics=dynamics, task=task, policies=tuple(policies),
                                                 driver=driver, robots=tuple(robots), tasks=tuple(tasks))}
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(result, indent=2) + "\n")
    return out


def figure_provenance(version: int, *, results: tuple[str | Path, ...] = (), **kwargs) -> dict:
    """A picture's provenance: :func:`provenance` (``kwargs``: what a simulation it ran depends on), and the sha256
    of each results file it is drawn from under ``"results"`` (a name under ``benchmarks/results/`` or a path), so
    that the picture goes stale with them."""
    record = provenance(version, **kwargs)
    if results:
        record["results"] = {_results_name(r): file_sha256(results_path(_results_name(r))) for r in results}
    return record


def _results_name(file: str | Path) -> str:
    path = Path(file)
    if not path.is_absolute():
        return str(file)
    path = path.resolve()
    return str(path.relative_to(RESULTS)) if path.is_relative_to(RESULTS) else _relative(path)


def save_figure(fig, path: str | Path, *, version: int, results: tuple[str | Path, ...] = (), dynamics: bool = False,
                task: bool = False, policies: tuple[str | Path, ...] = (), driver: bool = False,
                robots: tuple[str, ...] = (), script: str | Path | None = None, **savefig) -> Path:
    """Save a matplotlib figure as a PNG that carries its :func:`figure_provenance` (a ``tEXt`` chunk,
    :data:`PNG_KEY`), so that the docs build checks a picture as it checks a table; returns the path.

    Args:
        fig: the matplotlib figure.
        path: the PNG.
        version: the calling script's ``VERSION``.
        results: the results files the figure is drawn from; the picture goes stale when one changes or is stale.
        dynamics, task, policies, driver, robots, script: as :func:`provenance`, for a picture of a simulation run.
        **savefig: passed to ``fig.savefig`` (``dpi``, ``bbox_inches``).
    """
    import io

    record = figure_provenance(version, results=results, script=script, dynamics=dynamics, task=task,
                               policies=tuple(policies), driver=driver, robots=tuple(robots))
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", **savefig)
    return write_png_provenance(buffer.getvalue(), path, record)


def write_png_provenance(png: bytes, path: str | Path, record: dict) -> Path:
    """Write PNG bytes to ``path`` with ``record`` (a provenance dict, as JSON) in a ``tEXt`` chunk after ``IHDR``
    (any earlier provenance chunk dropped); for pictures not drawn by matplotlib (a screenshot, a video frame)."""
    chunks = [c for c in png_chunks(png) if not (c[0] == b"tEXt" and c[1].startswith(PNG_KEY.encode() + b"\0"))]
    text = PNG_KEY.encode("latin-1") + b"\0" + json.dumps(record, sort_keys=True).encode("latin-1")
    chunks.insert(1, (b"tEXt", text))
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_bytes(b"\x89PNG\r\n\x1a\n" + b"".join(
        struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data)) for kind, data in chunks))
    return out


def png_chunks(png: bytes) -> list[tuple[bytes, bytes]]:
    """A PNG's chunks, ``(type, data)`` in order (a tiny reader: no decoding, no checksum check)."""
    if png[:8] != b"\x89PNG\r\n\x1a\n":
        raise ValueError("not a PNG file")
    chunks, at = [], 8
    while at + 8 <= len(png):
        (size,), kind = struct.unpack(">I", png[at:at + 4]), png[at + 4:at + 8]
        chunks.append((kind, png[at + 8:at + 8 + size]))
        at += 12 + size
    return chunks


def png_provenance(path: str | Path) -> dict | None:
    """The provenance a PNG carries (:func:`save_figure`), or ``None`` when it has none."""
    for kind, data in png_chunks(Path(path).read_bytes()):
        key, _, text = data.partition(b"\0")
        if kind == b"tEXt" and key == PNG_KEY.encode():
            return json.loads(text.decode("latin-1"))
    return None


# --- reading results back: the docs' tables --------------------------------------------------------------------

class FigureError(Exception):
    """A page cites a figure that cannot be drawn (a missing file or key) or is stale."""


CITED: list[str] | None = None
"""While the docs hook renders a page, the results files its tables and values read (:func:`load_results`)."""


def results_path(name: str) -> Path:
    """A cited file's path: under ``benchmarks/results/``, or the repository's for ``docs/...``, ``benchmarks/...``."""
    return ROOT / name if name.startswith(("docs/", "benchmarks/")) else RESULTS / name


def load_results(name: str) -> dict:
    """Results file ``name`` (:func:`results_path`), noted in :data:`CITED` while a page renders.

    Raises:
        FigureError: the file is not there.
    """
    if CITED is not None and name not in CITED:
        CITED.append(name)
    path = results_path(name)
    if not path.is_file():
        raise FigureError(f"results file {name} not found ({path})")
    return json.loads(path.read_text())


def markdown_table(header: list[str], align: list[str], rows: list[list[str]]) -> str:
    """A Markdown table: a header row, an alignment row (``---``, ``---:``) and the rows."""
    lines = ["| " + " | ".join(header) + " |", "|" + "|".join(align) + "|"]
    lines += ["| " + " | ".join(row) + " |" for row in rows]
    return "\n".join(lines)


def markdown_cell(text: str) -> str:
    """``text`` on one line, safe in a table cell (double backticks made single, pipes escaped)."""
    return " ".join(str(text).split()).replace("``", "`").replace("|", "\\|")


def paired_difference(a: list, b: list) -> dict:
    """Two success series over the same episodes: the mean of ``a - b`` (``difference``), its 95 % confidence
    interval by the normal approximation (``ci95``), and the episodes only one of them succeeded in (``only_a``,
    ``only_b``)."""
    import math

    n = len(a)
    d = [float(x) - float(y) for x, y in zip(a, b, strict=True)]
    mean = sum(d) / n
    sd = math.sqrt(sum((x - mean) ** 2 for x in d) / (n - 1)) if n > 1 else float("nan")
    half = 1.96 * sd / math.sqrt(n)
    return {"difference": mean, "ci95": [mean - half, mean + half], "only_a": sum(bool(x) and not y for x, y in zip(a, b)),
            "only_b": sum(bool(y) and not x for x, y in zip(a, b))}


def logged_series(path: str | Path) -> list[tuple[int, float]]:
    """A training run's logged scalar (``logs/scalars/NAME.csv``: ``frames,value`` rows) as (frames, value) pairs;
    empty where the run never logged it."""
    path = Path(path)
    if not path.is_file():
        return []
    return [(int(a), float(b)) for a, b in (line.split(",") for line in path.read_text().splitlines() if line)]
