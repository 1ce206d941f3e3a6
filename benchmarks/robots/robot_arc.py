"""How far each robot turns on the nav world's ground when told to, and what its odometry makes of it.

Run: ``python -m benchmarks.robots.robot_arc [--linear 0.5] [--angular 0.5] [--seconds 6] [--starts 64]``

Each shipped robot, in the ``nav_deploy`` environment fitted to it (one world, the test set's first episode, the
nominal rover, no randomization), is sent one ``/cmd_vel`` (``--linear`` m/s, ``--angular`` rad/s) through its
base for ``--seconds`` from rest, on the nav world's terrain and on the same world made flat (``terrain="flat"``).
Per robot and ground: the yaw it was told to turn and the yaw it turned, the distance its chassis origin moved, the
distance its encoders read, and how far the fused odometry's position (the encoders along the gyro's heading: what
the deployable policies steer by) ended from the true one. The robot files' effective track factors were measured
on the flat arena (``benchmarks/robots/robot_check.py``). One start, one command: a probe. Then the survey: the same
command from the test set's first ``--starts`` starts at once, per robot and ground, the quartiles of the yaw each
world turned over the yaw commanded, and the share of starts that turned less than half of it; on the nav world
again with the other drivetrain (``nav_other_drivetrain``: a robot file's ``motor.per_side`` flipped, so the
Husky's and the Jackal's wheels turn freely and the ATRV-Jr's are geared per side), and with the ground contact 0.1
and 10 times as stiff (``STIFFNESS_SCALES``). Writes ``benchmarks/results/robot_arc.json``.
"""

from __future__ import annotations

import argparse
import math
import sys
import tempfile
from pathlib import Path

from benchmarks._common import write_results

VERSION = 5
"""This script's method, bumped by hand when what it measures or how changes (``_common.write_results``)."""

RESULTS = Path(__file__).resolve().parents[1] / "results"
GROUNDS = {"nav": None, "flat": "flat"}
"""Each ground the robots drive on: the nav world's own terrain (``nav_deploy``'s), and the same world made flat."""
STIFFNESS_SCALES = {"nav_softer": 0.1, "nav_stiffer": 10.0}
"""The survey on the nav world again, with the ground contact this many times as stiff (the robot's own is 1): how
the turn on uneven ground depends on the contact law."""


def other_drivetrain(robot: str, folder: Path) -> Path:
    """A copy of the shipped ``robot``'s file (and URDF) in ``folder`` with ``motor.per_side`` flipped."""
    import shutil

    from atrv_warp.core.robot import load_robot

    spec = load_robot(robot)
    urdf = Path(spec.urdf)
    shutil.copy(urdf, folder / urdf.name)
    text = Path(spec.path).read_text()
    if spec.motor_per_side:
        text = text.replace("per_side = true", "per_side = false")
    else:
        text = text.replace("[motor]\n", "[motor]\nper_side = true\n", 1)
    out = folder / f"{robot}_other_drivetrain.toml"
    out.write_text(text)
    assert load_robot(out).motor_per_side != spec.motor_per_side
    return out


def drive(robot: str, linear: float, angular: float, seconds: float, terrain: str | None = None) -> dict:
    import torch
    import warp as wp

    from atrv_warp.task.env import RoverEnv
    from atrv_warp.task.evaluation import EVAL_SEED

    env = RoverEnv(1, task="nav_deploy", robot=robot, **({"terrain": terrain} if terrain else {}))
    env.set_seed(EVAL_SEED)
    td = env.reset()
    sim, cfg = env.sim, env.task_cfg
    start, yaw0 = sim.root_pose[0, :2].clone().double(), float(sim.rpy[0, 2])
    action = torch.tensor([[linear / cfg.max_linear, angular / cfg.max_angular]])
    steps = round(seconds / sim.sim_cfg.step_dt)
    travelled, read, yaw = 0.0, 0.0, 0.0
    previous, previous_yaw = start, yaw0
    for _ in range(steps):
        td["action"] = action
        td = env.step(td)["next"]
        here, now = sim.root_pose[0, :2].clone().double(), float(sim.rpy[0, 2])
        travelled += float((here - previous).norm())
        yaw += math.remainder(now - previous_yaw, 2 * math.pi)
        previous, previous_yaw = here, now
        read += abs(float(wp.to_torch(sim.driver.state.odom_twist).view(-1, 2)[0, 0])) * sim.sim_cfg.step_dt
    fused = wp.to_torch(sim.driver.state.fused).view(-1, 3)[0].double()
    c, s = math.cos(yaw0), math.sin(yaw0)
    true_odom = torch.tensor([c * (previous[0] - start[0]) + s * (previous[1] - start[1]),
                              -s * (previous[0] - start[0]) + c * (previous[1] - start[1])])
    return {"steps": steps, "step_dt": sim.sim_cfg.step_dt, "yaw_commanded": angular * steps * sim.sim_cfg.step_dt,
            "yaw_turned": yaw, "distance_driven": travelled, "distance_encoders": read,
            "encoders_over_driven": read / travelled if travelled > 0 else None,
            "fused_position_error": float((fused[:2] - true_odom).norm())}


def turn_ratio(env, td, linear: float, angular: float, seconds: float, on_step=None):
    """(N,) float64: the yaw each world of ``env`` (reset, its tensordict ``td``) turned over the yaw commanded,
    ``linear`` [m/s] and ``angular`` [rad/s] sent as its action for ``seconds``; ``on_step(k, steps)`` is called after
    each step ``k``."""
    import torch

    sim, cfg = env.sim, env.task_cfg
    action = torch.tensor([[linear / cfg.max_linear, angular / cfg.max_angular]]).expand(sim.num_worlds, 2)
    steps = round(seconds / sim.sim_cfg.step_dt)
    previous = sim.rpy[:, 2].clone().double()
    yaw = torch.zeros(sim.num_worlds, dtype=torch.float64)
    for k in range(steps):
        td["action"] = action
        td = env.step(td)["next"]
        now = sim.rpy[:, 2].clone().double()
        yaw += torch.remainder(now - previous + math.pi, 2 * math.pi) - math.pi
        previous = now
        if on_step is not None:
            on_step(k, steps)
    return yaw / (angular * steps * sim.sim_cfg.step_dt)


def survey(robot: str | Path, linear: float, angular: float, seconds: float, starts: int,
           terrain: str | None = None, stiffness_scale: float = 1.0) -> dict:
    """:func:`drive`'s turn over the test set's first ``starts`` starts at once: how much of the commanded yaw each
    world turned (its quartiles), and how many turned less than half of it. ``stiffness_scale`` multiplies every
    world's contact stiffness after the reset (a study of the ground contact, not a shipped setting)."""
    import torch
    import warp as wp

    from atrv_warp.task.env import RoverEnv
    from atrv_warp.task.evaluation import EVAL_SEED

    options = {"terrain": terrain} if terrain else {}
    env = RoverEnv(starts, task="nav_deploy", robot=robot, **options)
    env.set_seed(EVAL_SEED)
    td = env.reset()
    sim = env.sim
    wp.to_torch(sim.params.physics.stiffness).mul_(stiffness_scale)
    ratio = turn_ratio(env, td, linear, angular, seconds)
    q = torch.quantile(ratio, torch.tensor([0.25, 0.5, 0.75], dtype=torch.float64)).tolist()
    return {"starts": starts, "stiffness_scale": stiffness_scale, "sim_dt": sim.sim_cfg.sim_dt,
            "turned_over_commanded": {"q25": q[0], "median": q[1], "q75": q[2]},
            "under_half": float((ratio < 0.5).double().mean())}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--linear", type=float, default=0.5, help="commanded forward speed [m/s]")
    parser.add_argument("--angular", type=float, default=0.5, help="commanded yaw rate [rad/s]")
    parser.add_argument("--seconds", type=float, default=6.0)
    parser.add_argument("--starts", type=int, default=64,
                        help="the survey: this many of the test set's starts at once, per robot and ground")
    parser.add_argument("--out", default=str(RESULTS / "robot_arc.json"))
    args = parser.parse_args(argv)
    if args.seconds <= 0 or args.starts <= 0:
        parser.error("--seconds and --starts must be > 0")
    from atrv_warp.core.robot import ROBOTS, load_robot

    rows = {}
    for robot in ROBOTS:
        rows[robot] = {ground: drive(robot, args.linear, args.angular, args.seconds, terrain)
                       for ground, terrain in GROUNDS.items()}
        for ground, r in rows[robot].items():
            print(f"{robot:8s} {ground:5s} yaw {r['yaw_turned']:.2f} of {r['yaw_commanded']:.2f} rad; drove {r['distance_driven']:.2f} m, "
                  f"encoders read {r['distance_encoders']:.2f} m; fused odometry off by "
                  f"{r['fused_position_error']:.2f} m", flush=True)
    surveys = {}
    with tempfile.TemporaryDirectory() as folder:
        for robot in ROBOTS:
            surveys[robot] = {ground: survey(robot, args.linear, args.angular, args.seconds, args.starts, terrain)
                              for ground, terrain in GROUNDS.items()}
            surveys[robot]["nav_other_drivetrain"] = survey(other_drivetrain(robot, Path(folder)), args.linear,
                                                            args.angular, args.seconds, args.starts)
            surveys[robot]["nav_other_drivetrain"]["motor_per_side"] = not load_robot(robot).motor_per_side
            for ground, scale in STIFFNESS_SCALES.items():
                surveys[robot][ground] = survey(robot, args.linear, args.angular, args.seconds, args.starts,
                                                GROUNDS[ground.split("_")[0]], scale)
            for ground, r in surveys[robot].items():
                t = r["turned_over_commanded"]
                print(f"{robot:8s} {ground:5s} over {r['starts']} starts: turned {t['median']:.2f} of the commanded "
                      f"yaw (quartiles {t['q25']:.2f}, {t['q75']:.2f}); under half on {100 * r['under_half']:.0f} % "
                      "of them", flush=True)
    result = {"linear": args.linear, "angular": args.angular, "seconds": args.seconds, "robots": rows,
              "survey": surveys}
    out = write_results(args.out, result, version=VERSION, task=True, driver=True, robots=tuple(ROBOTS))
    print(f"written to {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
