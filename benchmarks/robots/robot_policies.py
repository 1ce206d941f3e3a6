"""Each shipped robot's deployable nav policy on its own robot: the test set in our simulator, and the MuJoCo twin.

Run: ``python -m benchmarks.robots.robot_policies [--robots atrvjr jackal husky] [--episodes 1000] [--twin-episodes 200]
[--jobs 2]``; ``--robot-file FILE --policy PATH --out OUT`` runs a robot file's policy the same way (the six-wheel
test robot's: ``robot_policies_sixwheel.json``); ``--twin-geometric-radius`` configures the twin's base for the
wheels' geometric radius, as the twin did before (``robot_policies_geometric_radius.json``).

For each robot, its shipped ``nav_deploy_<robot>`` policy (trained at that robot's own limits, under ``wide``, by
the command :data:`~atrv_warp.policy.SHIPPED_POLICIES` names) runs its recorded task, fitted to its robot, once on
each of the first ``--episodes`` episodes of the test set (``EVAL_SEED``) under ``wide`` and on the nominal rover,
and once on each of the first ``--twin-episodes`` in the MuJoCo twin of the nav world at the nominal µ, its base as
the deploy docs advise (the task's velocity and acceleration limits, the robot's driver configured for the radius
the twin's tyres roll on, the encoders' odometry without the accelerometer), on the test set and again on the
validation set (``VALIDATION_SEED``). The targets: >= 90 % in ours under both, >= 90 % in the twin on both sets.

Per robot: its limits and control period, and per run the success rate, how the other episodes ended and its
seconds (``--jobs`` runs at once, so with more than one they share the cores). Prints
one table and writes ``benchmarks/results/robot_policies.json`` with each policy's sha256. The time each took to
train is its own results file's (``train_to_success_nav_deploy_<robot>.json``).
"""

from __future__ import annotations

import argparse
import concurrent.futures
import contextlib
import multiprocessing
import sys
import time
import types
from pathlib import Path

from benchmarks._common import load_results, markdown_table, write_results
from benchmarks.transfer.mujoco_transfer import ENDS, rates

VERSION = 2
"""This script's method (2: the twin on a second seed's episodes too, the validation set's), bumped by hand when what it measures or how changes (``_common.write_results``)."""

RESULTS = Path(__file__).resolve().parents[1] / "results"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robots", nargs="+", default=None, help="shipped robots (default: every one)")
    parser.add_argument("--episodes", type=int, default=1000, help="test-set episodes in our simulator")
    parser.add_argument("--twin-episodes", type=int, default=200, help="episodes in the MuJoCo twin (0: none)")
    parser.add_argument("--robot-file", metavar="FILE", default=None,
                        help="a robot file of one's own, run with its --policy instead of the shipped robots (write it "
                             "elsewhere with --out)")
    parser.add_argument("--policy", metavar="PATH", default=None, help="the --robot-file's policy (.pt)")
    parser.add_argument("--twin-geometric-radius", action="store_true",
                        help="configure the twin's base for the wheels' geometric radius, not the radius its tyres "
                             "roll on (the twin's default before; write it elsewhere with --out)")
    parser.add_argument("--out", default=str(RESULTS / "robot_policies.json"))
    parser.add_argument("--jobs", type=int, default=1,
                        help="evaluations run at once, each in its own process on one thread (default 1)")
    args = parser.parse_args(argv)
    if args.episodes < 1 or args.twin_episodes < 0 or args.jobs < 1:
        parser.error("--episodes and --jobs must be >= 1 and --twin-episodes >= 0")
    from atrv_warp.core.robot import ROBOTS
    from atrv_warp.policy import SHIPPED_POLICIES, policy_path, policy_record
    from atrv_warp.sim.config import nominal_rover_config
    from atrv_warp.sim.driver import DriverConfig
    from atrv_warp.task.evaluation import VALIDATION_SEED

    if (args.robot_file is None) != (args.policy is None):
        parser.error("--robot-file and --policy go together")
    if args.robot_file is not None and (args.robots or Path(args.out) == RESULTS / "robot_policies.json"):
        parser.error("--robot-file runs that robot alone: leave out --robots and give its own --out")
    if args.twin_geometric_radius and Path(args.out) == RESULTS / "robot_policies.json":
        parser.error("--twin-geometric-radius is a study: give it its own --out")
    robots = [args.robot_file] if args.robot_file else args.robots or list(ROBOTS)
    unknown = [r for r in robots if r not in ROBOTS and r != args.robot_file]
    if unknown:
        parser.error(f"unknown robot(s) {unknown}; shipped: {', '.join(ROBOTS)}")
    if args.twin_episodes:
        try:
            import mujoco  # noqa: F401
        except ImportError:
            print("MuJoCo is missing: pip install -e '.[mujoco]' (or --twin-episodes 0)", file=sys.stderr)
            return 2
    table, files, jobs = {}, [], []
    for robot in robots:
        name = args.policy or f"nav_deploy_{robot}"
        if args.policy is None and name not in SHIPPED_POLICIES:
            parser.error(f"no shipped policy {name!r} for robot {robot!r}")
        try:
            path = policy_path(name)
        except (FileNotFoundError, ValueError) as err:
            print(f"robot_policies.py: error: {' '.join(str(err).split())}", file=sys.stderr)
            return 2
        files.append(path)
        record = policy_record(path)
        task = record.task
        train = SHIPPED_POLICIES[name].train if args.policy is None else None
        row = {"policy": name, "train": train, "max_linear": task.config.max_linear,
               "max_angular": task.config.max_angular, "linear_max_acceleration": task.config.linear_max_acceleration,
               "control_period": task.config.control_period, "max_steps": task.config.max_steps}
        runs = [("wide", {"randomization": "wide", "episodes": args.episodes}),
                ("nominal", {"randomization": "none", "episodes": args.episodes})]
        if args.twin_episodes:
            twin = {"engine": "mujoco", "episodes": args.twin_episodes}
            if args.twin_geometric_radius:
                twin["driver"] = DriverConfig(wheel_radius=nominal_rover_config(robot).wheel_radius)
            runs += [("mujoco", twin), ("mujoco_other_seed", {**twin, "seed": VALIDATION_SEED})]
        own = {"robot": robot} if args.robot_file else {}  # a file's: evaluate takes its path, the table its name
        key = record.robot.name if args.robot_file else robot
        jobs += [(key, label, str(path), kw | own) for label, kw in runs]
        table[key] = row
    jobs.sort(key=lambda job: job[3].get("engine") != "mujoco")  # the twin's, the longest, first
    with _pool(args.jobs) as pool:
        for (robot, label, _, _), r in zip(jobs, pool.map(_evaluate, jobs), strict=True):
            table[robot][label] = r
            print(f"{robot:8s} {label:17s} " + " ".join(f"{k} {100 * r[k]:5.1f}%" for k in ENDS)
                  + f"  ({r['seconds']:.0f} s)", flush=True)
    result = {"seed": "EVAL_SEED", "other_seed": "VALIDATION_SEED", "episodes": args.episodes,
              "twin_episodes": args.twin_episodes, "twin_base_radius": "geometric" if args.twin_geometric_radius
              else "rolling", "jobs": args.jobs, "robots": table}
    pairs = ((policy_record(files[0]).task.name, args.robot_file),) if args.robot_file else ()  # by the file's path
    out = write_results(args.out, result, version=VERSION, task=True, driver=True, policies=tuple(files),
                        robots=tuple(robots), tasks=pairs)
    print(f"written to {out}")
    return 0


def _evaluate(job: tuple) -> dict:
    """One evaluation of ``main``'s: its rates and the seconds it took."""
    from atrv_warp.evaluate import evaluate_policy

    _, _, path, kw = job
    t0 = time.perf_counter()
    r = rates(evaluate_policy(path, **kw).record)
    r["seconds"] = round(time.perf_counter() - t0, 1)
    return r


def _pool(jobs: int):
    """``jobs`` processes of one thread each (spawned: Warp and torch start fresh), or this process for one."""
    if jobs == 1:
        return contextlib.nullcontext(types.SimpleNamespace(map=map))
    return concurrent.futures.ProcessPoolExecutor(jobs, mp_context=multiprocessing.get_context("spawn"),
                                                  initializer=_one_thread)


def _one_thread() -> None:
    import torch

    torch.set_num_threads(1)


# --- the figures' tables, drawn from the results files at docs build time --------------------------

def task_fit() -> str:
    """The ``nav_deploy`` task fitted to each shipped robot (:mod:`atrv_warp.task.scaling`), computed from the code."""
    from atrv_warp.core.robot import ROBOTS
    from atrv_warp.sim.config import RoverConfig
    from atrv_warp.task.registry import resolve_task
    from atrv_warp.task.scaling import fit_task

    declared = resolve_task("nav_deploy")
    rows = []
    for name in ROBOTS:
        c = fit_task(declared, RoverConfig(robot=name)).config
        period = c.control_period or 0.05
        acc = "-" if c.linear_max_acceleration is None else f"{c.linear_max_acceleration:g}"
        rows.append([f"`{name}`", f"{c.max_linear:g} / {c.max_angular:g}", acc, f"{period:g} s ({1 / period:g} Hz)",
                     f"{c.max_steps * period:g} s", f"{c.max_steps * period * c.max_linear:g} m",
                     f"{c.reach_radius:g} / {c.clearance_radius:g} m", f"{c.action_scale:g} N·m"])
    c = declared.config
    rows.append(["as declared (before robots had files)", f"{c.max_linear:g} / {c.max_angular:g}",
                 f"{c.linear_max_acceleration:g}", "0.05 s (20 Hz)", f"{c.max_steps * 0.05:g} s",
                 f"{c.max_steps * 0.05 * c.max_linear:g} m", f"{c.reach_radius:g} / {c.clearance_radius:g} m",
                 f"{c.action_scale:g} N·m"])
    return markdown_table(["robot", "action 1: m/s / rad/s", "a [m/s²]", "control period", "episode", "at full speed",
                   "reach / clearance radius", "torque action 1"], ["---"] + ["---:"] * 7, rows)


def robot_policies() -> str:
    """``robot_policies.json``: each shipped robot's deployable nav policy on its own robot (the test set under
    ``wide`` and nominal, and the MuJoCo twin), with the time it took to train from its own
    ``train_to_success_nav_deploy_<robot>.json``."""
    d = load_results("robot_policies.json")
    rows = []
    for name, r in d["robots"].items():
        train = load_results(f"train_to_success_nav_deploy_{name}.json")
        seeds = train["seeds"]
        reached = [s for s in seeds if s["reached"]]
        wall = train["median"]["wall_s_to_threshold"]
        if len(seeds) > 1:
            when = "not reached by every seed" if wall is None else f"{wall / 60:.1f} min (median of {len(seeds)})"
        else:
            when = f"{wall / 60:.1f} min" if wall is not None else "not reached"
        frames = f"{sorted(s['frames_to_threshold'] for s in reached)[len(reached) // 2]:,}" if reached else "-"
        twin, other = r.get("mujoco"), r.get("mujoco_other_seed")
        twin_cell = "-"
        if twin:
            twin_cell = f"{100 * twin['success']:.1f} % ({twin['episodes']})"
            twin_cell += f", {100 * other['success']:.1f} % on another seed" if other else ""
        rows.append([f"`{name}`", f"{r['max_linear']:g} m/s, {r['max_angular']:g} rad/s",
                     f"{r['control_period']:g} s", f"{100 * r['wide']['success']:.1f} %",
                     f"{100 * r['nominal']['success']:.1f} %",
                     twin_cell, when, frames])
    return markdown_table(["robot", "limits", "period", "`wide` (1,000)", "nominal (1,000)", "MuJoCo twin, nominal µ",
                   "90 % after", "frames then"], ["---"] + ["---:"] * 7, rows)


TABLES = {
    "robot_policies": robot_policies,
    "task_fit": task_fit,
}


if __name__ == "__main__":
    sys.exit(main())
