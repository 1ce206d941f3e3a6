"""The shipped ``follow_path`` policies: each on places and a map it never trained in, against Nav2's Regulated Pure
Pursuit on the same episodes, and how long its training took to reach 90 %.

Run: ``python -m benchmarks.training.follow_path_policies [--episodes 1000] [--robots atrvjr ...]
[--run ROBOT=RUN_DIR ...]`` (about six minutes a robot on 2 cores). For each robot whose ``follow_path_<robot>``
ships, one deterministic episode in each of ``--episodes`` worlds, seeded with the test set's seed
(``EVAL_SEED``), as ``python -m atrv_warp.evaluate follow_path_<robot> --map building:50@1000 yard:50@1000`` runs
them:

- **test places**: procedural buildings and yards of seeds the training preset never draws (it draws 0-31), nominal
  and under ``wide`` (each world's physics, sensor noise and latency drawn from the seed);
- **the example map**: ``atrv_warp/assets/maps/office.yaml`` (``docs/make_example_map.py``: an office floor laid
  out by hand, not by the generator the policies trained on), nominal, ``--map-episodes`` episodes;
- **the baseline**: ``atrv_warp.task.pursuit`` on the test places' nominal episodes, as ``evaluate --baseline``
  runs it. Both are handed the same plans, replanned every second with Nav2's obstacle layer, and every episode's
  first plan runs through an unmapped obstacle; the paired difference in success (policy - baseline) and its 95 %
  interval are reported.

The training's figures come from its run folder (``--run ROBOT=DIR``; default ``runs/follow_path_<robot>``, where
``python -m atrv_warp.train --config follow_path env.robot=<robot> run.name=follow_path_<robot>`` writes
it): its validation curve (256 episodes in the training places, under ``wide``, every 100,000 frames), the wall time
until it first reached 90 % and the training's minutes; the run's ``best_policy.pt`` must be the shipped file (its
sha256). Each nominal run also counts the collisions the robot met backing up (its mean commanded speed over the
last four steps below -0.1 of its limit: the laser looks forward). Written to
``benchmarks/results/follow_path_policies.json``.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from benchmarks._common import (
    file_sha256,
    load_results,
    logged_series,
    markdown_table,
    paired_difference,
    write_results,
)

VERSION = 2
"""This script's method, bumped by hand when what it measures or how changes (``_common.write_results``)."""

ROOT = Path(__file__).resolve().parents[2]
RESULTS = ROOT / "benchmarks" / "results"
ROBOTS = ("atrvjr", "husky", "jackal")
PLACES = ("building:50@1000", "yard:50@1000")
"""The test places: seeds from 1000 on (the training preset draws 0-31)."""
EXAMPLE_MAP = "atrv_warp/assets/maps/office.yaml"
THRESHOLD = 0.9


def paired(a: list[bool], b: list[bool]) -> dict:
    """The policy's success minus the baseline's over the same episodes, with its 95 % interval
    (:func:`~benchmarks._common.paired_difference`)."""
    p = paired_difference(a, b)
    return {"difference": p["difference"], "ci95": p["ci95"], "only_policy": p["only_a"], "only_baseline": p["only_b"]}


def training_figures(run_dir: Path, shipped: Path) -> dict:
    """The run's validation curve, when it first reached :data:`THRESHOLD` and its minutes, from its logs."""
    scalars = run_dir / "logs" / "scalars"
    success = dict(logged_series(scalars / "eval_success_rate.csv"))
    known = dict(logged_series(scalars / "eval_known_wall_s.csv") or logged_series(scalars / "wall_time_s.csv"))
    if not success:
        raise SystemExit(f"no training logs in {run_dir} (give --run ROBOT=RUN_DIR)")
    best = run_dir / "best_policy.pt"
    if file_sha256(best) != file_sha256(shipped):
        raise SystemExit(f"{best} is not the shipped {shipped} (copy it there, or give the run that trained it)")
    reached = next((f for f, r in sorted(success.items()) if r >= THRESHOLD - 1e-6), None)  # float32-logged rates
    final = json.loads((run_dir / "final_eval.json").read_text()) if (run_dir / "final_eval.json").is_file() else {}
    config = (run_dir / "config.toml").read_text() if (run_dir / "config.toml").is_file() else ""
    return {"run_dir": str(run_dir.relative_to(ROOT)) if run_dir.is_relative_to(ROOT) else str(run_dir),
            "config": config, "train_minutes": final.get("train_minutes"), "frames": final.get("frames"),
            "frames_to_threshold": reached, "wall_s_to_threshold": known.get(reached) if reached else None,
            "best_validation": max(success.values()),
            "eval_curve": [{"frames": f, "success_rate": r, "wall_s": known.get(f)} for f, r in sorted(success.items())]}


class BackingUp:
    """Per episode (one world each), whether its robot was backing up when it ended: the mean commanded linear
    speed over its last four steps below -0.1 of its limit (``attach`` for :func:`evaluate_policy`)."""

    STEPS = 4

    def __init__(self):
        self.at_end: list[bool] = []

    def attach(self, env):
        import torch

        recent: list[torch.Tensor] = []
        ended: dict[int, bool] = {}

        def on_step(_env, td):
            recent.append(td["action"][:, 0].detach().float().cpu().clamp(-1.0, 1.0))
            del recent[:-self.STEPS]
            mean = torch.stack(recent).mean(0)
            for w in torch.nonzero(td["next", "done"].reshape(-1).cpu()).flatten().tolist():
                ended.setdefault(w, bool(mean[w] < -0.1))
            self.at_end = [ended.get(w, False) for w in range(len(mean))]

        return on_step


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=1000)
    parser.add_argument("--map-episodes", type=int, default=200)
    parser.add_argument("--robots", nargs="+", default=list(ROBOTS))
    parser.add_argument("--run", action="append", default=[], metavar="ROBOT=RUN_DIR",
                        help="the run folder that trained a robot's shipped policy (default runs/follow_path_<robot>)")
    parser.add_argument("--out", default=str(RESULTS / "follow_path_policies.json"))
    parser.add_argument("--figure", default=None, metavar="PNG",
                        help="measure nothing: draw the first robot's policy driving episodes in the example map")
    args = parser.parse_args()
    runs = dict(item.split("=", 1) for item in args.run)
    if args.figure:
        print(f"figure: {draw_example_map(args.robots[0], Path(args.figure))}")
        return 0

    from atrv_warp.cli.evaluate import evaluate_policy
    from atrv_warp.policy import SHIPPED_POLICIES, shipped_policy_path
    from atrv_warp.task.evaluation import EVAL_SEED, format_result
    from atrv_warp.task.spec import END_REASONS

    def run(label: str, **kwargs):
        t0 = time.perf_counter()
        backing = BackingUp()
        evaluation = evaluate_policy(seed=EVAL_SEED, attach=backing.attach, **kwargs)
        result = evaluation.result
        print(format_result(label, result), f"({time.perf_counter() - t0:.0f} s)", flush=True)
        figures = result.as_dict() | {k: v for k, v in evaluation.extra.items()
                                      if k in ("success_median_path_ratio", "success_median_least_clearance_m")}
        reasons = [END_REASONS[int(r)] for r in evaluation.record.end_reason]
        figures["collision_backing_up_rate"] = sum(
            r in ("obstacle", "wall") and b for r, b in zip(reasons, backing.at_end, strict=True)) / len(reasons)
        return figures, [bool(s) for s in evaluation.record.success]

    rows, policies = [], []
    for robot in args.robots:
        name = f"follow_path_{robot}"
        if name not in SHIPPED_POLICIES:
            raise SystemExit(f"{name} is not a shipped policy")
        path = shipped_policy_path(name)
        policies.append(path)
        run_dir = Path(runs.get(robot, ROOT / "runs" / name))
        row = {"robot": robot, "policy": name, "train": SHIPPED_POLICIES[name].train,
               "training": training_figures(run_dir if run_dir.is_absolute() else ROOT / run_dir, path)}
        row["nominal"], ours = run(f"{name}, test places", policy=name, episodes=args.episodes, maps=PLACES)
        row["wide"], _ = run(f"{name}, test places, wide", policy=name, episodes=args.episodes, maps=PLACES,
                             randomization="wide")
        row["example_map"], _ = run(f"{name}, {EXAMPLE_MAP}", policy=name, episodes=args.map_episodes,
                                    maps=(str(ROOT / EXAMPLE_MAP),))
        row["baseline"], theirs = run(f"pure pursuit on {robot}, test places", baseline=True, task="follow_path",
                                      robot=robot, episodes=args.episodes, maps=PLACES)
        row["policy_minus_baseline"] = paired(ours, theirs)
        rows.append(row)
    out = write_results(args.out, {"benchmark": "follow_path_policies", "seed": EVAL_SEED, "episodes": args.episodes,
                                   "places": list(PLACES), "example_map": EXAMPLE_MAP,
                                   "example_map_sha256": file_sha256(ROOT / EXAMPLE_MAP), "threshold": THRESHOLD,
                                   "rows": rows},
                        version=VERSION, task=True, driver=True, policies=tuple(policies), robots=tuple(args.robots))
    print(f"written to {out}")
    return 0


def draw_example_map(robot: str, out: Path, episodes: int = 6) -> Path:
    """``follow_path_<robot>`` on the first ``episodes`` episodes of the test seed in the example map: the map, each
    episode's first plan (dashed), the path its robot drove (solid), its start, its goal and its unmapped obstacles
    (shaded, in its colour)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    from atrv_warp.cli.evaluate import evaluate_policy
    from atrv_warp.policy import shipped_policy_path
    from atrv_warp.sim.contact import OBSTACLE_KINDS
    from atrv_warp.task.evaluation import EVAL_SEED
    from atrv_warp.task.spec import END_REASONS
    from atrv_warp.world import load_map

    name = f"follow_path_{robot}"
    drive: dict = {"plans": None, "poses": [], "last": np.full(episodes, -1)}

    def attach(env):
        def on_step(env_, td):
            base = getattr(env_, "base_env", env_)
            if drive["plans"] is None:  # the plans the episodes started with (the first replan is a second in)
                drive["plans"] = [base.path[w, :int(base.path_length[w])].cpu().numpy().copy()
                                  for w in range(base.num_envs)]
                drive["goals"] = base.target.cpu().numpy().copy()
                o = base.sim.obstacles  # the unmapped obstacles: (kind, x, y, yaw, half sides) per slot
                drive["obstacles"] = (o.kind.cpu().numpy().copy(), o.pose.cpu().numpy().copy(),
                                      o.size.cpu().numpy().copy())
            drive["poses"].append(base.sim.root_pose[:, :2].cpu().numpy().copy())
            done = td["next", "done"].reshape(-1).cpu().numpy()
            drive["last"] = np.where((drive["last"] < 0) & done, len(drive["poses"]), drive["last"])
        return on_step

    evaluation = evaluate_policy(name, episodes=episodes, seed=EVAL_SEED, maps=(str(ROOT / EXAMPLE_MAP),),
                                 attach=attach)
    site = load_map(ROOT / EXAMPLE_MAP)
    poses = np.stack(drive["poses"])
    fig, ax = plt.subplots(figsize=(9, 6.4), dpi=100)
    (x0, y0), (w, h) = site.origin, site.size
    shade = np.where(site.walls, 0.15, 1.0)
    ax.imshow(shade, origin="lower", cmap="gray", vmin=0, vmax=1, extent=(x0, x0 + w, y0, y0 + h))
    colours = plt.get_cmap("tab10")
    kinds, poses_o, sizes = drive["obstacles"]
    for k in range(episodes):
        c, end = colours(k), int(drive["last"][k])
        for kind, (ox, oy, yaw), (a, b) in zip(kinds[k], poses_o[k], sizes[k], strict=True):
            if kind == OBSTACLE_KINDS["cylinder"]:
                ax.add_patch(plt.Circle((ox, oy), a, color=c, alpha=0.45))
            elif kind == OBSTACLE_KINDS["box"]:
                corners = np.array([[a, b], [-a, b], [-a, -b], [a, -b]]) @ np.array(
                    [[np.cos(yaw), np.sin(yaw)], [-np.sin(yaw), np.cos(yaw)]])
                ax.add_patch(plt.Polygon(corners + [ox, oy], color=c, alpha=0.45))
        plan = drive["plans"][k]
        ax.plot(plan[:, 0], plan[:, 1], "--", color=c, lw=1)
        ax.plot(poses[:end, k, 0], poses[:end, k, 1], "-", color=c, lw=2,
                label=f"episode {k}: {END_REASONS[int(evaluation.record.end_reason[k])]}")
        ax.plot(*poses[0, k], "o", color=c, ms=5)
        gx, gy = drive["goals"][k]
        ax.plot(gx, gy, "*", color=c, ms=12, mec="k", mew=0.5)
    ax.set_xlim(x0 + 0.5, x0 + w - 0.5)
    ax.set_ylim(y0 + 0.5, y0 + h - 0.5)
    ax.set_aspect("equal")
    ax.set_xlabel("x [m] (map frame)")
    ax.set_ylabel("y [m]")
    ax.legend(loc="upper left", fontsize=7, ncol=3, bbox_to_anchor=(0.0, -0.09))
    ax.set_title(f"{name} in {Path(EXAMPLE_MAP).name}: the first plan (dashed), the path driven (solid), start (o), "
                 "goal (*), unmapped obstacles (shaded)", fontsize=9)
    fig.tight_layout()
    from benchmarks._common import save_figure

    save_figure(fig, out, version=VERSION, task=True, driver=True, policies=(shipped_policy_path(name),),
                robots=(robot,))
    plt.close(fig)
    return out


# --- the figures' tables, drawn from the results files at docs build time --------------------------

def _pct(x: float) -> str:
    return f"{100 * x:.1f} %"


def follow_path_policies() -> str:
    """``follow_path_policies.json``: each shipped follow_path policy on the test places (nominal, ``wide``), the
    example map, against pure pursuit on the same episodes, and its training's time to 90 %."""
    rows = []
    for r in load_results("follow_path_policies.json")["rows"]:
        d, t = r["policy_minus_baseline"], r["training"]
        reached = "not reached" if t["wall_s_to_threshold"] is None else f"{t['wall_s_to_threshold'] / 60:.1f} min"
        collisions = r["nominal"]["obstacle_rate"] + r["nominal"]["wall_rate"]
        backing = r["nominal"].get("collision_backing_up_rate")
        rows.append([f"`{r['policy']}`", f"**{_pct(r['nominal']['success_rate'])}**", _pct(collisions)
                     + (f" ({_pct(backing)} backing up)" if backing is not None else ""),
                     f"**{_pct(r['wide']['success_rate'])}**", f"**{_pct(r['example_map']['success_rate'])}**",
                     _pct(r["baseline"]["success_rate"]),
                     f"{100 * d['difference']:+.1f} ({100 * d['ci95'][0]:+.1f} to {100 * d['ci95'][1]:+.1f})",
                     reached, f"{t['train_minutes']:.0f} min" if t["train_minutes"] is not None else "-"])
    return markdown_table(["policy", "test places", "collision", "wide", "office map", "pure pursuit",
                           "difference [points, 95 %]", "to 90 %", "trained"],
                          ["---"] + ["---:"] * 8, rows)


TABLES = {
    "follow_path_policies": follow_path_policies,
}


if __name__ == "__main__":
    sys.exit(main())
