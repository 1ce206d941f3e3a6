"""Sim-to-sim transfer, measured: deployable nav policies in the MuJoCo twin of the nav world (issue #41).

    pip install -e ".[mujoco]"
    python -m benchmarks.transfer.mujoco_transfer [POLICY ...] [--episodes 200] [--frictions 0.3 0.5 0.8] [--out FILE]

Each POLICY (a ``.pt`` file, a shipped name, or an exported ``.pt2``; default: the shipped ``nav_deploy``) runs
deterministically on the first ``--episodes`` episodes of the evaluation set (:data:`~atrv_warp.task.evaluation.
EVAL_SEED`: the worlds, starts and goals ``python -m atrv_warp.evaluate`` runs), in the twin at each µ of
``--frictions`` (0.3 is the nominal µ), its observation built by the light core's ``RobotObservation`` from the
twin's odometry, IMU, scan and goal, as on a robot. Label a policy ``NAME=PATH`` (e.g. ``randomized=run1.pt
plain=run2.pt``). The same policies in our simulator on the same episodes (``--ours``, at the nominal rover) give
the engine gap beside it. ``--odometry truth`` feeds the policies the chassis' true pose in place of the fused
odometry (a study: what the odometry's error costs in each engine; ``--ours`` then stays on the odometry).
``--driver-wheel-radius M`` configures the twin's base with a calibrated wheel radius, as a rover engineer sets
their base's after ``atrv-calibrate``.

Per policy and µ: the success rate and the failure breakdown (obstacle, timeout, flip, wall, nonfinite), printed
as one table and written to ``benchmarks/results/mujoco_transfer.json``. The issue's target: the randomized
deployable policy >= 80 % in the twin at the nominal µ over >= 200 episodes.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from benchmarks._common import labelled, load_results, markdown_table, write_results

VERSION = 1
"""This script's method, bumped by hand when what it measures or how changes (``_common.write_results``)."""

RESULTS = Path(__file__).resolve().parents[1] / "results"
ENDS = ("success", "obstacle", "timeout", "flip", "wall", "nonfinite")


def rates(record) -> dict:
    r = record.summary()
    return {"episodes": r.episodes, "success": r.success_rate, "obstacle": r.obstacle_rate,
            "timeout": r.timeout_rate, "flip": r.flip_rate, "wall": r.wall_rate, "nonfinite": r.nonfinite_rate,
            "mean_steps": r.mean_steps}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("policies", nargs="*", default=["nav_deploy"], metavar="[NAME=]POLICY",
                        help="deployable policies (default: the shipped nav_deploy)")
    parser.add_argument("--episodes", type=int, default=200)
    parser.add_argument("--seed", type=int, default=None, help="evaluation set (default: EVAL_SEED)")
    parser.add_argument("--frictions", type=float, nargs="+", default=[0.3, 0.5, 0.8])
    parser.add_argument("--ours", action="store_true", help="also run each policy in our simulator")
    parser.add_argument("--odometry", choices=("fused", "truth"), default="fused",
                        help="the pose the policies see their goal from in the twin: the base's fused odometry (as "
                             "on a robot), or the true pose (a study of what the odometry's error costs)")
    parser.add_argument("--driver-wheel-radius", type=float, default=None, metavar="M",
                        help="the twin's base configured with this wheel radius [m] (e.g. atrv-calibrate's fit of a "
                             "bag recorded from the twin; default: the nominal rover's)")
    parser.add_argument("--driver-accel-time", type=float, default=None, metavar="S",
                        help="the twin's base fuses its accelerometer into the odometry's speed with this time "
                             "constant [s] (DriverConfig.odometry_accel_time; default: the encoders alone)")
    parser.add_argument("--out", default=str(RESULTS / "mujoco_transfer.json"))
    args = parser.parse_args(argv)
    if args.episodes < 1:
        parser.error("--episodes must be >= 1")
    try:
        import mujoco  # noqa: F401
    except ImportError:
        print("MuJoCo is missing: pip install -e '.[mujoco]'", file=sys.stderr)
        return 2
    from atrv_warp.integrations.mujoco import DeployablePolicy, draw_episodes, run_twin_episodes
    from atrv_warp.policy import policy_path
    from atrv_warp.task.evaluation import EVAL_SEED

    seed = EVAL_SEED if args.seed is None else args.seed
    policies, files = {}, []
    for item in args.policies:
        label, path = labelled(item)
        try:
            policies[label] = DeployablePolicy.load(path)
        except (FileNotFoundError, ValueError) as err:
            print(f"mujoco_transfer.py: error: cannot load policy {path}: {' '.join(str(err).split())}", file=sys.stderr)
            return 2
        files.append(path if path.endswith(".pt2") else str(policy_path(path)))
    tasks = {p.task for p in policies.values()}
    if len(tasks) != 1:
        print(f"mujoco_transfer.py: error: the policies were trained on different tasks {sorted(tasks)}", file=sys.stderr)
        return 2
    task = tasks.pop()
    robots = {p.robot for p in policies.values()}
    if len(robots) != 1:
        print(f"mujoco_transfer.py: error: the policies were trained on different robots {sorted(robots)}",
              file=sys.stderr)
        return 2
    robot = robots.pop()
    episodes = draw_episodes(task, args.episodes, seed=seed, robot=robot)
    from atrv_warp.sim.driver import DriverConfig

    try:
        driver = DriverConfig(wheel_radius=args.driver_wheel_radius, odometry_accel_time=args.driver_accel_time)
    except ValueError as err:
        parser.error(str(err))
    table = {}
    for name, policy in policies.items():
        table[name] = {}
        for mu in args.frictions:
            t0 = time.perf_counter()
            table[name][f"mujoco µ {mu:g}"] = r = rates(run_twin_episodes(policy, episodes, friction=mu,
                                                                                odometry=args.odometry, driver=driver))
            r["seconds"] = time.perf_counter() - t0
            print(f"{name:16s} mujoco µ {mu:<4g} " + " ".join(f"{k} {100 * r[k]:5.1f}%" for k in ENDS)
                  + f"  ({r['seconds']:.0f} s)", flush=True)
        path = files[list(policies).index(name)]
        if args.ours and not path.endswith(".pt2"):  # our simulator runs the .pt (an exported file is for robots)
            from atrv_warp.evaluate import evaluate_policy

            run = evaluate_policy(path, episodes=args.episodes, seed=seed, driver=driver)
            table[name]["ours (nominal µ 0.3)"] = r = rates(run.record)
            print(f"{name:16s} ours          " + " ".join(f"{k} {100 * r[k]:5.1f}%" for k in ENDS), flush=True)
    result = {"task": getattr(task, "name", task), "robot": robot, "seed": seed, "episodes": args.episodes,
              "odometry": args.odometry,
              "driver_wheel_radius": args.driver_wheel_radius, "driver_accel_time": args.driver_accel_time,
              "frictions": args.frictions, "policies": table}
    out = write_results(args.out, result, version=VERSION, task=True, driver=True,
                        policies=tuple(f for f in files if Path(f).is_file()))
    print(f"written to {out}")
    return 0


# --- the figures' tables, drawn from the results files at docs build time --------------------------

def mujoco_transfer(name: str = "mujoco_transfer.json") -> str:
    """``mujoco_transfer.json``: each deployable policy in the MuJoCo twin at each µ (and in our simulator on the
    same episodes), success and how the others ended."""
    rows = []
    for policy, runs in load_results(name)["policies"].items():
        for where, r in runs.items():
            rows.append([policy, where, str(r["episodes"]), f"{r['success']:.1%}", f"{r['obstacle']:.1%}",
                         f"{r['timeout']:.1%}", f"{r['flip']:.1%}", f"{r['mean_steps']:.0f}"])
    return markdown_table(["policy", "where", "episodes", "success", "obstacle", "timeout", "flip", "mean steps"],
                          ["---", "---", "---:", "---:", "---:", "---:", "---:", "---:"], rows)


TABLES = {
    "mujoco_transfer": mujoco_transfer,
    "mujoco_transfer_plain": lambda: mujoco_transfer("mujoco_transfer_plain.json"),
    "mujoco_transfer_truth_odometry": lambda: mujoco_transfer("mujoco_transfer_truth_odometry.json"),
    "mujoco_transfer_accel_odometry": lambda: mujoco_transfer("mujoco_transfer_accel_odometry.json"),
    "mujoco_transfer_wide_slip": lambda: mujoco_transfer("mujoco_transfer_wide_slip.json"),
    "mujoco_transfer_wide_slip_gain": lambda: mujoco_transfer("mujoco_transfer_wide_slip_gain.json"),
}


if __name__ == "__main__":
    sys.exit(main())
