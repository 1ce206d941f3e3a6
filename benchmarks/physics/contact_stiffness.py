"""Why the turn on uneven ground depends on the contact stiffness: a contact patch against one point, the geared
sides' chain inside the friction solve, and each wheel's load, at 0.1, 1 and 10 times the nominal stiffness, on the
nav terrain and on flat ground.

    python -m benchmarks.physics.contact_stiffness [--figure docs/turn_vs_stiffness.png]

Each shipped robot, in ``nav_deploy``'s world fitted to it (the test set's first ``STARTS`` starts, nominal rover,
no randomization), is sent one ``/cmd_vel`` (0.5 m/s, 0.5 rad/s) through its base for 6 s. Per robot, ground,
stiffness (``ContactConfig.stiffness`` x ``SCALES``), contact (``point``: the tangent plane at the deepest rim point;
``patch``: ``ContactConfig.patch`` = ``PATCH``, the terrain's mean over +-0.3 radius along the rim and the wheel's
width; ``chain``, for a robot with one motor per side: one point, and ``ContactConfig.solve_geared_sides``, each side's
wheels turned as one inside the solve) and substep (``SUBSTEPS``: converged where the finer ones agree): the median over the starts of the yaw
turned over the yaw commanded, and the share of wheel-steps (the last two thirds of the drive) whose load is under a
quarter of its chassis' mean wheel load, estimated from each hub's height over the ground under it (``kp d^1.5``).
At 10x the stiffness also with the contact damping 10x (the damping that keeps ``kc / kp``). Writes
``benchmarks/results/contact_stiffness.json``; ``--figure`` draws the turn against the stiffness.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from benchmarks._common import load_results, markdown_table, pin_to_one_core, save_figure, write_results
from benchmarks.robots.robot_arc import turn_ratio

VERSION = 2
"""This script's method, bumped by hand when what it measures or how changes (``_common.write_results``)."""

RESULTS = Path(__file__).resolve().parents[1] / "results"
SCALES = (0.1, 1.0, 10.0)
"""Contact stiffness over the nominal."""
PATCH = 0.3
"""``ContactConfig.patch`` of the patch contact: +-0.3 wheel radius along the rim."""
SUBSTEPS = (0.01, 0.005, 0.0025)
"""Solver substeps [s]: the nominal and two finer."""
STARTS = 64
SECONDS = 6.0
COMMAND = (0.5, 0.5)
"""(linear [m/s], angular [rad/s])."""
LOW_LOAD = 0.25
"""A wheel under this share of its chassis' mean wheel load is all but lifted."""


def drive(robot: str, terrain: str | None, scale: float, patch: float, sim_dt: float, damping_scale: float = 1.0,
          chain: bool = False) -> dict:
    """One survey: the median turn over the commanded and the share of low-loaded wheel-steps."""
    import numpy as np
    import torch

    from atrv_warp.sim.config import ContactConfig, SimConfig
    from atrv_warp.task.env import RoverEnv
    from atrv_warp.task.evaluation import EVAL_SEED

    nominal = ContactConfig()
    contact = ContactConfig(stiffness=nominal.stiffness * scale, damping=nominal.damping * damping_scale, patch=patch,
                            solve_geared_sides=chain)
    env = RoverEnv(STARTS, task="nav_deploy", robot=robot, contact=contact, sim=SimConfig(sim_dt=sim_dt),
                   **({"terrain": terrain} if terrain else {}))
    env.set_seed(EVAL_SEED)
    td = env.reset()
    sim = env.sim
    wheels, per_world = sim.built.wheel_bodies, sim.built.rover_builder.body_count
    low = []

    def loads(k: int, steps: int) -> None:  # the last two thirds: each wheel's load against its chassis' mean
        if k >= steps // 3:
            hubs = sim.state_0.body_q.numpy().reshape(STARTS, per_world, 7)[:, wheels, :3]
            finite = np.isfinite(hubs).all(axis=(1, 2))
            hubs = np.where(finite[:, None, None], hubs, 0.0)
            depth = np.maximum(_ground(sim, hubs) - (hubs[..., 2] - sim.rover_cfg.wheel_radius), 0.0)
            load = depth ** 1.5
            low.append((load < LOW_LOAD * load.mean(axis=1, keepdims=True))[finite])

    ratio = turn_ratio(env, td, *COMMAND, SECONDS, on_step=loads)
    finite = torch.isfinite(ratio)
    return {"turned": float(ratio[finite].median()), "low_load_share": float(np.concatenate(low).mean()),
            "nonfinite": int((~finite).sum())}


def _ground(sim, hubs):
    """The ground's height [m] under each hub (N, W, 3): the terrain's bilinear height, or the flat ground's top."""
    import numpy as np

    top = sim.arena_cfg.ground_top
    grid = sim.terrain.grid
    if grid is None:
        return np.full(hubs.shape[:2], top)
    n = grid.heights.shape[1]
    fx = np.clip((hubs[..., 0] + grid.half_size) / grid.resolution, 0, n - 1 - 1e-3)
    fy = np.clip((hubs[..., 1] + grid.half_size) / grid.resolution, 0, n - 1 - 1e-3)
    i, j = fx.astype(int), fy.astype(int)
    u, v = fx - i, fy - j
    h = grid.heights[sim.terrain.tile.cpu().numpy()]  # (N, n, n): each world's tile
    rows = np.arange(len(hubs))[:, None]
    return (h[rows, i, j] * (1 - u) * (1 - v) + h[rows, i + 1, j] * u * (1 - v) + h[rows, i, j + 1] * (1 - u) * v
            + h[rows, i + 1, j + 1] * u * v + top)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--figure", type=Path, help="draw the turn against the stiffness into this PNG")
    parser.add_argument("--figure-only", action="store_true", help="only draw the figure from the results file")
    args = parser.parse_args()
    if not args.figure_only:
        pin_to_one_core()
        from atrv_warp.core.robot import ROBOTS, load_robot

        rows = []
        for robot in ROBOTS:
            contacts = [("point", 0.0, False), ("patch", PATCH, False)]
            contacts += [("chain", 0.0, True)] if load_robot(robot).motor_per_side else []
            for ground, terrain in (("nav", None), ("flat", "flat")):
                for scale in SCALES:
                    for contact, patch, chain in contacts:
                        for sim_dt in SUBSTEPS:
                            row = {"robot": robot, "ground": ground, "stiffness": scale, "contact": contact,
                                   "sim_dt": sim_dt, "damping": 1.0,
                                   **drive(robot, terrain, scale, patch, sim_dt, chain=chain)}
                            rows.append(row)
                            print(" ".join(f"{k} {v:.3g}" if isinstance(v, float) else f"{k} {v}"
                                           for k, v in row.items()), flush=True)
                rows.append({"robot": robot, "ground": ground, "stiffness": 10.0, "contact": "point",
                             "sim_dt": SUBSTEPS[-1], "damping": 10.0,
                             **drive(robot, terrain, 10.0, 0.0, SUBSTEPS[-1], damping_scale=10.0)})
                print(rows[-1], flush=True)
        path = write_results(RESULTS / "contact_stiffness.json", {"rows": rows, "summary": summarize(rows),
                                                                  "command": list(COMMAND), "starts": STARTS,
                                                                  "seconds": SECONDS},
                             version=VERSION, task=True, driver=True, robots=tuple(ROBOTS))
        print(f"wrote {path}")
    if args.figure:
        draw(args.figure)
    return 0


def summarize(rows: list[dict]) -> dict:
    """The figures the docs quote, per robot: the share of low-loaded wheel-steps on the nav terrain at the nominal
    and at ten times the stiffness (finest substep), and the median turn there at ten times the stiffness, one point
    at the nominal and the finest substep and, for geared sides, with the chain in the solve at the nominal."""
    out: dict = {"low_load_x1": {}, "low_load_x10": {}, "point_x10": {}, "point_x10_fine": {}, "chain_x10": {},
                 "point_x1": {}}
    for robot in dict.fromkeys(r["robot"] for r in rows):
        fine, coarse = converged(rows, robot, "nav"), converged(rows, robot, "nav", sim_dt=SUBSTEPS[0])
        chain = converged(rows, robot, "nav", "chain", sim_dt=SUBSTEPS[0])
        out["low_load_x1"][robot], out["low_load_x10"][robot] = fine[1.0]["low_load_share"], fine[10.0]["low_load_share"]
        out["point_x1"][robot], out["point_x10"][robot] = coarse[1.0]["turned"], coarse[10.0]["turned"]
        out["point_x10_fine"][robot] = fine[10.0]["turned"]
        if chain:
            out["chain_x10"][robot] = chain[10.0]["turned"]
    return out


def converged(rows: list[dict], robot: str, ground: str, contact: str = "point", damping: float = 1.0,
              sim_dt: float = SUBSTEPS[-1]) -> dict:
    """Each stiffness' figures at a substep (default the finest, ``SUBSTEPS[-1]``)."""
    return {r["stiffness"]: r for r in rows if (r["robot"], r["ground"], r["contact"], r["sim_dt"], r["damping"])
            == (robot, ground, contact, sim_dt, damping)}


def draw(path: Path, results: str = "contact_stiffness.json") -> None:
    """The median turn against the stiffness, per robot: nav and flat ground, point and patch contact."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = load_results(results)["rows"]
    robots = list(dict.fromkeys(r["robot"] for r in rows))
    fig, axes = plt.subplots(1, len(robots), figsize=(4.0 * len(robots), 3.4), sharey=True)
    for ax, robot in zip(axes, robots):
        for ground, contact, style in (("nav", "point", "-o"), ("nav", "patch", "--s"), ("nav", "chain", "-D"),
                                       ("flat", "point", "-^")):
            got = converged(rows, robot, ground, contact, sim_dt=SUBSTEPS[0])
            xs = sorted(got)
            if xs:
                ax.plot(xs, [got[x]["turned"] for x in xs], style, label=f"{ground}, {contact}")
        ax.legend(loc="lower left", fontsize=8)
        ax.set_xscale("log")
        ax.set_ylim(0, 1.05)
        ax.set_title(robot)
        ax.set_xlabel("contact stiffness / nominal")
    axes[0].set_ylabel("yaw turned / commanded")
    fig.suptitle("median over 64 starts, 0.01 s substep", fontsize=9)
    fig.tight_layout()
    save_figure(fig, path, version=VERSION, results=(results,), dpi=110)
    plt.close(fig)
    print(f"wrote {path}")


# --- the figures' tables, drawn from the results files at docs build time --------------------------

def contact_stiffness() -> str:
    """``contact_stiffness.json``: per robot and stiffness, the turn and the low-loaded wheels (finest substep)."""
    rows = load_results("contact_stiffness.json")["rows"]
    out = []

    def cell(got: dict, scale: float, key: str = "turned") -> str:
        return f"{100 * got[scale][key]:.0f} %" if scale in got else "-"

    for robot in dict.fromkeys(r["robot"] for r in rows):
        nav, patch, chain, flat = (converged(rows, robot, g, c, sim_dt=SUBSTEPS[0]) for g, c in
                                   (("nav", "point"), ("nav", "patch"), ("nav", "chain"), ("flat", "point")))
        fine, fine_chain = converged(rows, robot, "nav", "point"), converged(rows, robot, "nav", "chain")
        for scale in SCALES:
            out.append([f"`{robot}`", f"{scale:g}x", f"{cell(nav, scale)} ({cell(fine, scale)})", cell(patch, scale),
                        f"{cell(chain, scale)} ({cell(fine_chain, scale)})", cell(nav, scale, "low_load_share"),
                        cell(flat, scale)])
    return markdown_table(["robot", "stiffness", "nav: turned, point (at 0.0025 s)", "patch",
                           "chain in the solve (at 0.0025 s)", "nav: wheels under 1/4 load", "flat: turned"],
                          ["---", "---:", "---:", "---:", "---:", "---:", "---:"], out)


TABLES = {"contact_stiffness": contact_stiffness}


if __name__ == "__main__":
    sys.exit(main())
