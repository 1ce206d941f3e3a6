"""The gallery's pictures (``docs/gallery.md``): ``python docs/make_gallery.py``.

- ``docs/gallery_robots.png``: each shipped robot drawn from its URDF's collision geometry, from above and from
  the side, with its chassis, wheels and laser, and the limits its robot file declares;
- ``docs/gallery_tasks.png``: one episode of each shipped task, driven by its shipped policy: ``reach`` and ``nav``
  on the ATRV-Jr (wheel torques), and ``nav_deploy`` (``/cmd_vel`` at the robot's own limits) on each robot, all on
  the first episode of the test set;
- ``docs/gallery.json``: how each episode ended, the captions written from them and the pictures' provenance (the
  policies' sha256, the robot files', the dynamics and task fingerprints), which the page reads at build time.
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import sys
from pathlib import Path

import numpy as np
import torch

DOCS = Path(__file__).resolve().parent
ROOT = DOCS.parent
VERSION = 2
"""This script's method (which episodes, which policies, how drawn), bumped by hand when it changes."""

ROBOTS = ("atrvjr", "jackal", "husky")
EPISODES = (("reach", "atrvjr", "reach"), ("nav", "atrvjr", "nav"), ("nav_deploy", "atrvjr", "nav_deploy_atrvjr"),
            ("nav_deploy", "jackal", "nav_deploy_jackal"), ("nav_deploy", "husky", "nav_deploy_husky"))
"""(task, robot, shipped policy) of each task panel."""


def _common():
    spec = importlib.util.spec_from_file_location("benchmarks_common", ROOT / "benchmarks" / "_common.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def outlines(robot: str) -> tuple[list[tuple[str, np.ndarray]], np.ndarray]:
    """Each collision shape of ``robot``'s URDF as (its kind, vertices (V, 3) [m] in the root link's frame), and the
    laser's origin (3,) [m] in the same frame."""
    import yourdfpy

    from atrv_warp.core.robot import load_robot

    spec = load_robot(robot)
    urdf = yourdfpy.URDF.load(str(spec.urdf), build_scene_graph=True, load_meshes=False)
    around = np.linspace(0.0, 2.0 * np.pi, 48, endpoint=False)
    shapes = []
    for link in urdf.robot.links:
        for collision in link.collisions:
            pose = urdf.get_transform(link.name) @ (collision.origin if collision.origin is not None else np.eye(4))
            g = collision.geometry
            if g.box is not None:
                corners = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)]) * np.asarray(g.box.size) / 2
                shapes.append(("box", corners @ pose[:3, :3].T + pose[:3, 3]))
            elif g.cylinder is not None:
                r, half = g.cylinder.radius, g.cylinder.length / 2
                ring = np.stack([r * np.cos(around), r * np.sin(around)], -1)
                local = np.concatenate([np.c_[ring, np.full(len(ring), z)] for z in (-half, half)])
                shapes.append(("cylinder", local @ pose[:3, :3].T + pose[:3, 3]))
            elif g.sphere is not None:
                r = g.sphere.radius
                local = np.array([[r * np.cos(a) * np.cos(b), r * np.sin(a) * np.cos(b), r * np.sin(b)]
                                  for a in around[::4] for b in np.linspace(-1.5, 1.5, 7)])
                shapes.append(("sphere", local + pose[:3, 3]))
    return shapes, urdf.get_transform(spec.laser_frame)[:3, 3]


def _hull(points: np.ndarray) -> np.ndarray:
    """The convex hull (K, 2) of 2-D ``points``, counter-clockwise (Andrew's monotone chain)."""
    pts = sorted({(round(float(x), 5), round(float(y), 5)) for x, y in points})
    if len(pts) < 3:
        return np.asarray(pts)

    def half(seq):
        out: list[tuple[float, float]] = []
        for p in seq:
            while len(out) >= 2 and ((out[-1][0] - out[-2][0]) * (p[1] - out[-2][1])
                                     - (out[-1][1] - out[-2][1]) * (p[0] - out[-2][0])) <= 0:
                out.pop()
            out.append(p)
        return out

    return np.asarray(half(pts)[:-1] + half(reversed(pts))[:-1])


def draw_robots(out: Path) -> dict:
    """Top and side views of each shipped robot; returns each robot's caption facts."""
    import matplotlib.pyplot as plt
    from matplotlib.patches import Polygon

    from atrv_warp.core.robot import load_robot

    facts = {}
    fig, axes = plt.subplots(2, len(ROBOTS), figsize=(4.2 * len(ROBOTS), 6.4), dpi=90,
                             gridspec_kw={"height_ratios": [3, 2]})
    for col, robot in enumerate(ROBOTS):
        spec = load_robot(robot)
        shapes, laser = outlines(robot)
        body = np.concatenate([v for _, v in shapes])
        every = np.concatenate([body, laser[None]])
        for row, (i, j, view) in enumerate(((0, 1, "from above"), (0, 2, "from the side"))):
            ax = axes[row, col]
            # nearer shapes drawn last: from above the highest, from the side the nearest (lowest y)
            for kind, vertices in sorted(shapes, key=lambda s: float(s[1][:, 2].mean() if j == 1 else -s[1][:, 1].mean())):
                ax.add_patch(Polygon(_hull(vertices[:, [i, j]]), closed=True, edgecolor="k", lw=0.5, alpha=0.9,
                                     facecolor="0.25" if kind == "cylinder" else "tab:orange"))
            ax.plot(laser[i], laser[j], "o", color="tab:red", ms=6)
            lo, hi = every[:, [i, j]].min(0) - 0.1, every[:, [i, j]].max(0) + 0.1
            ax.set_xlim(lo[0], hi[0])
            ax.set_ylim(lo[1], hi[1])
            ax.set_aspect("equal")
            ax.grid(alpha=0.3)
            ax.set_xlabel("x [m] (forward)")
            ax.set_ylabel("y [m]" if j == 1 else "z [m]")
            if row == 0:
                lim = spec.limits
                ax.set_title(f"{spec.title}\n{lim.linear_velocity:g} m/s, {lim.angular_velocity:g} rad/s; "
                             f"{view}", fontsize=9)
            else:
                ax.set_title(view, fontsize=9)
        facts[robot] = {"title": spec.title, "linear_velocity": spec.limits.linear_velocity,
                        "angular_velocity": spec.limits.angular_velocity,
                        "length_m": round(float(np.ptp(body[:, 0])), 3), "width_m": round(float(np.ptp(body[:, 1])), 3)}
    fig.suptitle("the shipped robots, drawn from their URDFs' collision shapes (wheels dark, laser red)", fontsize=10)
    fig.tight_layout()
    _common().save_figure(fig, out, version=VERSION, script=__file__, dynamics=False, robots=ROBOTS)
    plt.close(fig)
    return facts


def episode(task: str, robot: str, policy: str, seed: int) -> dict:
    """The chassis path of the first episode of the test set (``seed``) of ``task`` on ``robot``, and its scene."""
    from tensordict import TensorDict

    from atrv_warp import RoverEnv, load_policy
    from atrv_warp.core.robot import robot_spec
    from atrv_warp.policy import policy_record
    from atrv_warp.task.spec import END_REASONS

    trained = policy_record(policy)  # the task it trained on, fitted to its robot: not today's declaration
    assert trained.task.name == task and trained.robot.name == robot, (policy, trained.task.name, trained.robot.name)
    env = RoverEnv(1, task=trained.task, robot=robot_spec(trained.robot), seed=seed)
    act = load_policy(policy)
    td = env.reset()
    path = [env.sim.root_pose[0, :2].clone()]
    reason, steps = 0, 0
    for steps in range(1, env.task_cfg.max_steps + 1):
        td = env.step(act(TensorDict(observation=td["observation"], batch_size=[1])))["next"]
        path.append(env.sim.root_pose[0, :2].clone())
        if bool(td["done"][0, 0]):
            reason = int(td["end_reason"][0, 0])
            break
    grid = env.sim.terrain.grid
    return {"path": torch.stack(path).numpy(), "target": env.target[0].clone().numpy(),
            "reach": env.task_cfg.reach_radius, "reason": END_REASONS[reason],
            "steps": steps, "heights": None if grid is None else grid.heights[int(env.sim.terrain.tile[0])],
            "half": None if grid is None else grid.half_size, "kind": env.sim.obstacles.kind[0].clone().numpy(),
            "pose": env.sim.obstacles.pose[0].clone().numpy(), "size": env.sim.obstacles.size[0].clone().numpy()}


def draw_tasks(out: Path, seed: int) -> dict:
    """One panel per (task, robot) of :data:`EPISODES`; returns each episode's outcome."""
    import matplotlib.pyplot as plt
    from matplotlib.patches import Circle, Polygon

    from atrv_warp.integrations.topdown import obstacle_shapes
    from atrv_warp.policy import shipped_policy_path

    fig, axes = plt.subplots(1, len(EPISODES), figsize=(3.6 * len(EPISODES), 4.0), dpi=90)
    outcomes = {}
    for ax, (task, robot, policy) in zip(axes, EPISODES):
        run = episode(task, robot, policy, seed)
        start, target = run["path"][0], run["target"]
        lo = np.minimum(start, target) - 2.5
        span = float((np.maximum(start, target) + 2.5 - lo).max())
        if run["heights"] is not None:
            h = run["half"]
            ax.imshow(run["heights"].T, origin="lower", extent=(-h, h, -h, h), cmap="gist_earth", alpha=0.6)
        for kind, shape in obstacle_shapes(run["kind"], run["pose"], run["size"]):
            patch = (Circle(tuple(shape[:2]), shape[2], color="0.2") if kind == "cylinder"
                     else Polygon(shape, closed=True, color="0.2"))
            ax.add_patch(patch)
        ax.add_patch(Circle(tuple(target), run["reach"], color="tab:blue", alpha=0.35))
        ax.plot(run["path"][:, 0], run["path"][:, 1], "-", lw=2, color="tab:orange")
        ax.plot(*start, "o", color="k")
        ax.set_xlim(lo[0], lo[0] + span)
        ax.set_ylim(lo[1], lo[1] + span)
        ax.set_aspect("equal")
        ax.set_title(f"{task} on the {robot}: {run['reason']} after {run['steps']} steps", fontsize=9)
        outcomes[f"{task}/{robot}"] = {"policy": policy, "reason": run["reason"], "steps": run["steps"]}
    fig.suptitle(f"the first test episode (seed {seed}) of each shipped task and robot: start (o), path, target "
                 "(disc), obstacles (dark), terrain (shaded)", fontsize=10)
    fig.tight_layout()
    _common().save_figure(fig, out, version=VERSION, script=__file__, dynamics=True, task=True, driver=True,
                          policies=tuple(str(shipped_policy_path(p)) for _, _, p in EPISODES), robots=ROBOTS)
    plt.close(fig)
    return outcomes


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seed", type=int, default=None, help="episode seed (default: the test set's)")
    args = parser.parse_args()

    from atrv_warp.policy import shipped_policy_path
    from atrv_warp.task.evaluation import EVAL_SEED

    seed = EVAL_SEED if args.seed is None else args.seed
    policies = tuple(str(shipped_policy_path(p)) for _, _, p in EPISODES)
    record = _common().provenance(VERSION, script=__file__, task=True, driver=True, policies=policies, robots=ROBOTS)
    robots = draw_robots(DOCS / "gallery_robots.png")
    tasks = draw_tasks(DOCS / "gallery_tasks.png", seed)
    ended = ", ".join(f"{k.replace('/', ' on the ')} {v['reason']} in {v['steps']} steps" for k, v in tasks.items())
    (DOCS / "gallery.json").write_text(json.dumps({
        "seed": seed, "robots": robots, "tasks": tasks,
        "caption": f"The first test episode (seed {seed}) of each shipped task, each driven by its shipped policy: "
                   f"{ended}.",
        "provenance": record}, indent=2) + "\n")
    print(f"wrote docs/gallery_robots.png, docs/gallery_tasks.png, docs/gallery.json ({ended})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
