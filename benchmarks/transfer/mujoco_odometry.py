"""How far each engine's wheel odometry runs from the truth when the deployable policy drives the nav episodes.

    pip install -e ".[mujoco]"
    python -m benchmarks.transfer.mujoco_odometry [--policy nav_deploy] [--episodes 40] [--frictions 0.3 0.8]
                                         [--contacts noslip sphere]

The policy drives the first ``--episodes`` episodes of the evaluation set in the MuJoCo twin at each µ, and in our
simulator on the nominal rover (µ 0.3), as ``benchmarks/transfer/mujoco_transfer.py`` runs them. Per episode, over its
steps: the distance the wheel encoders report (the odometry's |forward speed| x 0.05 s, summed) over the distance
the chassis travelled (its path in the ground plane), the largest gap between the goal distance seen from the
fused odometry and the true one [m], and the chassis' mean |yaw rate| over the mean |commanded yaw rate|. Printed
as medians over the episodes, with the success rate, and written to ``benchmarks/results/mujoco_odometry.json``.

Then what the twin's over-read is made of:

- **Its contact, varied** (``--contacts``, at the nominal µ 0.3, the same episodes): ``noslip``, MuJoCo's post-solve
  that removes the soft constraints' slip from the friction (10 iterations), and ``sphere``, each wheel a sphere of
  its radius, one contact under the axle as ours has (the tyre then sinks twice as far).
- **Scripted drives from rest** (``DRIVES``, through the task's base, no policy) in both engines at each µ: the
  encoders' distance over the path in the launch (the first ``LAUNCH_S``, the base's acceleration limit
  ramping the wheels) and in the steady drive after it, straight and on arcs.
"""

from __future__ import annotations

import argparse
import statistics
import sys
from pathlib import Path

import numpy as np

from benchmarks._common import load_results, markdown_table, write_results

VERSION = 2
"""This script's method, bumped by hand when what it measures or how changes (``_common.write_results``)."""

RESULTS = Path(__file__).resolve().parents[1] / "results"
STEP = 0.05
"""The policy's step [s]."""
DRIVES = ((1.0, 0.0), (1.0, 1.0), (0.5, 1.5), (1.5, 0.5))
"""Scripted /cmd_vel (linear [m/s], angular [rad/s]), each held from rest for ``DRIVE_S``."""
DRIVE_S = 4.0
"""[s] each scripted drive lasts."""
LAUNCH_S = 1.5
"""[s] of a scripted drive counted as its launch; the rest is its steady drive."""


CONTACTS = {"noslip": {"noslip_iterations": 10}, "sphere": {"wheel": "sphere"}}
"""``--contacts``' names: the :class:`~atrv_warp.integrations.mujoco.mjcf.MujocoContact` fields each changes from
the twin's contact."""


def summarize(episodes: list[dict]) -> dict:
    """Medians over episodes (and the success rate) of the per-episode figures."""
    return {"episodes": len(episodes), "success": statistics.fmean(e["success"] for e in episodes),
            **{f"median_{k}": statistics.median(e[k] for e in episodes)
               for k in ("encoder_over_true_path", "worst_goal_error_m", "yaw_rate_over_command")}}


def episode_figures(true_xy: np.ndarray, encoder_speed: np.ndarray, seen: np.ndarray, true_distance: np.ndarray,
                    yaw_rate: np.ndarray, command_yaw_rate: np.ndarray, success: bool) -> dict:
    path = float(np.linalg.norm(np.diff(true_xy, axis=0), axis=1).sum())
    return {"success": float(success), "encoder_over_true_path": float(np.abs(encoder_speed).sum() * STEP / max(path, 1e-6)),
            "worst_goal_error_m": float(np.abs(seen - true_distance).max()),
            "yaw_rate_over_command": float(np.abs(yaw_rate).mean() / max(np.abs(command_yaw_rate).mean(), 1e-6))}


def twin_episode(policy, episodes, episode, mu: float, contact=None) -> dict:
    """One episode in the twin at µ ``mu`` (``contact``: its MuJoCo contact settings): its :func:`episode_figures`."""
    from atrv_warp.integrations.mujoco import run_twin_episode
    from atrv_warp.task.spec import EndReason

    task = episodes.task
    twin = episodes.twin(episode, friction=mu, contact=contact)
    rec = []
    target, goal = np.asarray(episode.target), np.asarray(episode.goal)
    reason, _, _ = run_twin_episode(policy, twin, episode, task, on_step=lambda t: rec.append(
        (t.root_pose[:2].copy(), t.odom_twist[0], np.linalg.norm(goal - t.fused[:2]), t.angular_velocity[2],
         t.twist[1])))
    xy = np.array([r[0] for r in rec])
    return episode_figures(xy, np.array([r[1] for r in rec]), np.array([r[2] for r in rec]),
                           np.linalg.norm(xy - target, axis=1), np.array([r[3] for r in rec]),
                           np.array([r[4] for r in rec]), reason == int(EndReason.SUCCESS))


def ours_run(path: str, count: int, seed: int) -> list[dict]:
    import torch

    from atrv_warp.policy import load_policy
    from atrv_warp.task.env import ATRVjrEnv
    from atrv_warp.task.evaluation import run_episodes

    env = ATRVjrEnv(count, task="nav_deploy")
    rec = []

    def on_step(env_, td):
        sim = env_.sim
        rec.append((sim.root_pose[:, :2].clone(), sim.driver.odom_twist[:, 0].clone(),
                    td["next", "observation"][:, 0].clone(), env_.target_distance.clone(), sim.ang_vel[:, 2].clone(),
                    sim.driver.twist[:, 1].clone(), td["next", "done"].reshape(-1).clone()))

    record = run_episodes(load_policy(path, task="nav_deploy"), env, seed=seed, on_step=on_step)
    stacked = [torch.stack([r[k] for r in rec]).numpy() for k in range(7)]
    xy, enc, seen, true, yaw, cmd, done = stacked
    out = []
    for i in range(count):
        n = int(np.argmax(done[:, i])) + 1 if done[:, i].any() else len(done)
        out.append(episode_figures(xy[:n, i], enc[:n, i], seen[:n, i], true[:n, i], yaw[:n, i], cmd[:n, i],
                                   bool(record.success[i])))
    return out


def encoders_over_path(step, steps: int, launch: int) -> dict:
    """Encoders' distance over the path in the first ``launch`` of ``steps`` calls of ``step()`` (each returns the
    chassis' (x, y) [m] and the odometry's forward speed [m/s] after one step) and in the rest."""
    encoder, path, prev = [0.0, 0.0], [0.0, 0.0], None
    for k in range(steps):
        xy, speed = step()
        phase = int(k >= launch)
        if prev is not None:
            encoder[phase] += abs(speed) * STEP
            path[phase] += float(np.linalg.norm(xy - prev))
        prev = xy
    return {"launch": encoder[0] / max(path[0], 1e-6), "steady": encoder[1] / max(path[1], 1e-6)}


def ours_stepper(mu: float, driver, linear: float, angular: float):
    """One rover of our simulator at µ ``mu`` through ``driver``, commanded (``linear``, ``angular``) each step."""
    import torch

    from atrv_warp.sim import RoverSim
    from atrv_warp.sim.config import ContactConfig

    sim, twist = RoverSim(1, contact=ContactConfig(friction=mu), driver=driver), torch.tensor([[linear, angular]])

    def step():
        sim.set_twist(twist)
        sim.step()
        return sim.root_pose[0, :2].double().numpy(), float(sim.driver.odom_twist[0, 0])

    return step


def twin_stepper(mu: float, driver, linear: float, angular: float):
    """The twin on flat ground at µ ``mu`` through ``driver``, commanded (``linear``, ``angular``) each step."""
    from atrv_warp.integrations.mujoco import MujocoTwin

    twin = MujocoTwin(friction=mu, driver=driver)

    def step():
        twin.command(linear, angular)
        twin.step()
        return twin.root_pose[:2].copy(), float(twin.odom_twist[0])

    return step


def scripted_drives(task, mu: float) -> list[dict]:
    """Each of :data:`DRIVES` from rest in our simulator and in the twin at µ ``mu``, through ``task``'s base (the
    nominal rover's radius and track, as the simulator node configures a base): encoders' distance over the path,
    in the launch and in the steady drive."""
    from atrv_warp.integrations.mujoco.record import twin_driver

    driver = task.driver(twin_driver())
    steps, launch = round(DRIVE_S / STEP), round(LAUNCH_S / STEP)
    return [{"mu": mu, "linear": linear, "angular": angular,
             **{engine: encoders_over_path(stepper(mu, driver, linear, angular), steps, launch)
                for engine, stepper in (("ours", ours_stepper), ("twin", twin_stepper))}}
            for linear, angular in DRIVES]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--policy", default="nav_deploy")
    parser.add_argument("--episodes", type=int, default=40)
    parser.add_argument("--frictions", type=float, nargs="+", default=[0.3, 0.8])
    parser.add_argument("--contacts", nargs="*", default=["noslip", "sphere"], metavar="NAME",
                        help=f"the twin's contact varied, at µ 0.3 (known: {', '.join(CONTACTS)}; none: skip)")
    parser.add_argument("--out", default=str(RESULTS / "mujoco_odometry.json"))
    args = parser.parse_args(argv)
    unknown = [c for c in args.contacts if c not in CONTACTS]
    if unknown:
        parser.error(f"--contacts: unknown {', '.join(unknown)}; known: {', '.join(CONTACTS)}")
    try:
        import mujoco  # noqa: F401
    except ImportError:
        print("MuJoCo is missing: pip install -e '.[mujoco]'", file=sys.stderr)
        return 2
    import torch

    torch.set_num_threads(1)
    from atrv_warp.integrations.mujoco import DeployablePolicy, draw_episodes
    from atrv_warp.policy import policy_path
    from atrv_warp.task.evaluation import EVAL_SEED

    policy = DeployablePolicy.load(args.policy)
    episodes = draw_episodes(policy.task, args.episodes, seed=EVAL_SEED)
    rows = {}
    for mu in args.frictions:
        rows[f"mujoco µ {mu:g}"] = summarize([twin_episode(policy, episodes, e, mu) for e in episodes.episodes])
    from atrv_warp.integrations.mujoco.mjcf import MujocoContact

    for name in args.contacts:
        contact = MujocoContact(**CONTACTS[name])
        rows[f"mujoco µ 0.3, {name}"] = summarize([twin_episode(policy, episodes, e, 0.3, contact)
                                                  for e in episodes.episodes])
    rows["ours (nominal µ 0.3)"] = summarize(ours_run(str(policy_path(args.policy)), args.episodes, EVAL_SEED))
    for where, r in rows.items():
        print(f"{where:22s} success {100 * r['success']:5.1f}%  encoders / true path {r['median_encoder_over_true_path']:.3f}"
              f"  goal seen off by up to {r['median_worst_goal_error_m']:.2f} m  yaw rate / command "
              f"{r['median_yaw_rate_over_command']:.2f}  (medians over {r['episodes']} episodes)", flush=True)
    drives = [row for mu in args.frictions for row in scripted_drives(episodes.task, mu)]
    print(f"\nscripted drives from rest, encoders / path (launch: the first {LAUNCH_S:g} s; steady: the rest of "
          f"{DRIVE_S:g} s)")
    for d in drives:
        print(f"µ {d['mu']:g}  {d['linear']:.1f} m/s {d['angular']:.1f} rad/s   ours launch {d['ours']['launch']:.3f} "
              f"steady {d['ours']['steady']:.3f}   twin launch {d['twin']['launch']:.3f} steady "
              f"{d['twin']['steady']:.3f}", flush=True)
    out = write_results(args.out, {"benchmark": "mujoco_odometry", "policy": args.policy, "seed": EVAL_SEED,
                                   "episodes": args.episodes, "rows": rows, "contacts": args.contacts,
                                   "drives": drives, "drive_s": DRIVE_S, "launch_s": LAUNCH_S},
                        version=VERSION, task=True, driver=True, policies=(str(policy_path(args.policy)),))
    print(f"written to {out}")
    return 0


# --- the figures' tables, drawn from the results files at docs build time --------------------------

def mujoco_odometry_drives() -> str:
    """``mujoco_odometry.json``'s scripted drives: encoders' distance over the path, launch and steady, per engine."""
    d = load_results("mujoco_odometry.json")
    rows = [[f"{r['mu']:g}", f"{r['linear']:g} m/s, {r['angular']:g} rad/s",
             *(f"{r[engine][phase]:.3f}" for engine in ("ours", "twin") for phase in ("launch", "steady"))]
            for r in d["drives"]]
    return markdown_table(["µ", "command", "ours, launch", "ours, steady", "twin, launch", "twin, steady"],
                          ["---", "---", "---:", "---:", "---:", "---:"], rows)


TABLES = {
    "mujoco_odometry_drives": mujoco_odometry_drives,
}


if __name__ == "__main__":
    sys.exit(main())
