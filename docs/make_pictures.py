"""Pictures for the README and the docs pages, straight from the simulator: ``python docs/make_pictures.py``.

Runs the shipped policy on the first episodes of the standard evaluation set (seed 2024) and
draws, with matplotlib, from the chassis poses the simulator produced:

- ``docs/trajectories.png``: top-down view of the arena with every episode's path, coloured by
  world, its start and its target (the 1 m success disc);
- ``docs/episode.gif``: one episode animated, the rover's footprint (from the URDF's chassis
  box) turning toward its target and driving there;
- ``docs/nav.png``: four episodes of the navigation task (``--task nav``'s first worlds) over
  their terrain (shaded by height) and obstacles, driven by the scripted driver (dashed) and by
  the shipped navigation policy (solid); ``docs/nav.json`` beside it holds how each episode ended,
  the caption written from those outcomes (the docs page reads it at build time) and the
  picture's provenance (the policy's sha256, the dynamics and task fingerprints);
- ``docs/eval_video_frame.png`` (with ``--nav`` too): a frame of ``evaluate --video --video-follow 10``
  on four nav episodes of the shipped navigation policy, each panel following its rover;
- with ``--viewer``: ``docs/viewer.png``, the Rerun web viewer showing four recorded nav episodes of
  the shipped navigation policy in its default layout, served on localhost and photographed in
  headless Chromium through the code path of ``tests/test_browser.py`` (needs Debian's
  ``chromium`` and the ``browser`` extra).

Every PNG carries its provenance (``benchmarks/_common.save_figure``: the policies' sha256, the dynamics and task
fingerprints), which the docs build checks as it checks a results file.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import torch

DOCS = Path(__file__).resolve().parent
sys.path.insert(0, str(DOCS.parent))  # the benchmarks package

from benchmarks import _common

VERSION = 3
"""This script's method (which episodes, which drivers), bumped by hand when it changes; recorded with the caption."""


def rollout(num_episodes: int, seed: int) -> dict:
    """First episode of each world: chassis x, y, yaw per step until it ended, targets, end reasons."""
    from tensordict import TensorDict

    from atrv_warp import ATRVjrEnv, load_policy
    from atrv_warp.policy import pretrained_policy_path
    from atrv_warp.task.spec import END_REASONS

    env = ATRVjrEnv(num_episodes, seed=seed)
    policy = load_policy(pretrained_policy_path())
    td = env.reset()
    target = env.target.clone().numpy()
    poses = [torch.cat([env.sim.root_pose[:, :2], env.sim.rpy[:, 2:3]], -1).clone()]
    ended = torch.zeros(num_episodes, dtype=torch.bool)
    reason = torch.zeros(num_episodes, dtype=torch.long)
    length = torch.full((num_episodes,), env.task_cfg.max_steps)
    for t in range(env.task_cfg.max_steps):
        td = env.step(policy(TensorDict(observation=td["observation"], batch_size=[num_episodes])))["next"]
        poses.append(torch.cat([env.sim.root_pose[:, :2], env.sim.rpy[:, 2:3]], -1).clone())
        newly = td["done"][:, 0] & ~ended
        reason[newly] = td["end_reason"][newly, 0]
        length[newly] = t + 1
        ended |= newly
        if bool(ended.all()):
            break
    chassis = env.sim.description.chassis_box
    return {"poses": torch.stack(poses).numpy(), "target": target, "length": length.numpy(),
            "reason": [END_REASONS[int(r)] for r in reason], "half_size": env.sim.arena_cfg.half_size,
            "reach": env.task_cfg.reach_radius, "footprint": 2 * chassis[1][:2] if chassis is not None else (0.6, 0.4),
            "dt": env.sim.sim_cfg.step_dt, "policy": pretrained_policy_path()}


def _arena(ax, h: float) -> None:
    from matplotlib.patches import Rectangle

    ax.add_patch(Rectangle((-h, -h), 2 * h, 2 * h, fill=False, lw=3, color="0.35"))  # the walls' inner faces
    ax.set_xlim(-h - 1, h + 1)
    ax.set_ylim(-h - 1, h + 1)
    ax.set_aspect("equal")
    ax.grid(alpha=0.25)
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")


def draw_trajectories(run: dict, out: Path) -> None:
    import matplotlib.pyplot as plt
    from matplotlib.patches import Circle

    fig, ax = plt.subplots(figsize=(6.4, 6.4), dpi=110)
    _arena(ax, run["half_size"])
    colors = plt.get_cmap("tab10")
    for w in range(len(run["length"])):
        c = colors(w % 10)
        xy = run["poses"][: run["length"][w] + 1, w, :2]
        ax.plot(xy[:, 0], xy[:, 1], color=c, lw=2)
        ax.plot(*xy[0], "o", color=c, ms=6)
        ax.add_patch(Circle(tuple(run["target"][w]), run["reach"], color=c, alpha=0.25))
        ax.plot(*run["target"][w], "x", color=c, ms=8, mew=2)
    ok = sum(r == "success" for r in run["reason"])
    ax.set_title(f"shipped policy, {len(run['length'])} evaluation episodes: {ok} reached their target\n"
                 "(o start, x target, disc = 1 m success radius)", fontsize=10)
    fig.tight_layout()
    _common.save_figure(fig, out, version=VERSION, script=__file__, task=True, policies=(run["policy"],))
    plt.close(fig)


def draw_episode(run: dict, world: int, out: Path, every: int = 2) -> None:
    import matplotlib.pyplot as plt
    from matplotlib import animation
    from matplotlib.patches import Circle, Polygon

    from atrv_warp.integrations.topdown import box_corners

    n = int(run["length"][world]) + 1
    traj = run["poses"][:n, world]
    lx, ly = run["footprint"][0] / 2, run["footprint"][1] / 2
    fig, ax = plt.subplots(figsize=(4.2, 4.2), dpi=80)
    target = run["target"][world]
    lo = np.minimum(traj[:, :2].min(0), target) - 2.0
    hi = np.maximum(traj[:, :2].max(0), target) + 2.0
    span = (hi - lo).max()
    ax.set_xlim(lo[0], lo[0] + span)
    ax.set_ylim(lo[1], lo[1] + span)
    ax.set_aspect("equal")
    ax.grid(alpha=0.25)
    ax.add_patch(Circle(tuple(target), run["reach"], color="tab:blue", alpha=0.25))
    ax.plot(*target, "x", color="tab:blue", ms=9, mew=2)
    (trail,) = ax.plot([], [], color="tab:orange", lw=2)
    body = ax.add_patch(Polygon(box_corners(0.0, 0.0, 0.0, lx, ly), closed=True, color="tab:red"))
    title = ax.set_title("")

    def frame(i: int):
        body.set_xy(box_corners(*traj[i], lx, ly))
        trail.set_data(traj[: i + 1, 0], traj[: i + 1, 1])
        title.set_text(f"t = {i * run['dt']:.2f} s")
        return body, trail, title

    frames = list(range(0, n, every)) + [n - 1]
    anim = animation.FuncAnimation(fig, frame, frames=frames, blit=False)
    anim.save(out, writer=animation.PillowWriter(fps=round(1 / (run["dt"] * every))))
    plt.close(fig)


def nav_paths(policy, episodes: int, seed: int, task="nav", robot=None) -> dict:
    """Chassis paths of the first episode of each world on the navigation task ``task`` (``nav``, or ``nav_deploy``,
    which draws the same worlds, starts and targets for a seed; a name or a saved policy's recorded
    :class:`~atrv_warp.task.definition.Task`) on ``robot`` (default: the ATRV-Jr), and the scene."""
    from tensordict import TensorDict

    from atrv_warp import ATRVjrEnv
    from atrv_warp.task.spec import END_REASONS

    env = ATRVjrEnv(episodes, task=task, seed=seed, robot=robot)
    td = env.reset()
    scene = {"target": env.target.clone().numpy(), "tile": env.sim.terrain.tile.clone().numpy(),
             "kind": env.sim.obstacles.kind.clone().numpy(), "pose": env.sim.obstacles.pose.clone().numpy(),
             "size": env.sim.obstacles.size.clone().numpy()}
    paths = [env.sim.root_pose[:, :2].clone()]
    reason = torch.zeros(episodes, dtype=torch.long)
    for _ in range(env.task_cfg.max_steps):
        td = env.step(policy(TensorDict(observation=td["observation"], batch_size=[episodes])))["next"]
        live = reason == 0
        paths.append(torch.where(live[:, None], env.sim.root_pose[:, :2], paths[-1]))
        reason = torch.where(live & td["done"][:, 0], td["end_reason"][:, 0], reason)
        if bool((reason != 0).all()):
            break
    grid = env.sim.terrain.grid
    return {**scene, "paths": torch.stack(paths).numpy(), "reason": [END_REASONS[int(r)] for r in reason],
            "heights": grid.heights, "half": grid.half_size, "reach": env.task_cfg.reach_radius}


def _count(reasons: list[str], what: str) -> str:
    n = sum(r == what for r in reasons)
    return {0: f"none of the {len(reasons)}", len(reasons): f"all {n}"}.get(n, f"{n} of the {len(reasons)}")


def nav_caption(outcomes: dict[str, list[str]], seed: int) -> str:
    """The nav picture's caption, from how each driver's episodes ended."""
    scripted, policy = outcomes["scripted driver"], outcomes["nav policy (SAC)"]
    deploy = outcomes[DEPLOY]
    return (f"The first {len(policy)} episodes of the nav task's test set (seed {seed}), the same for the three "
            f"drivers. The scripted driver (dashed) reaches the target in {_count(scripted, 'success')} and runs into "
            f"an obstacle in {_count(scripted, 'obstacle')}; the shipped nav policy (wheel torques from arena "
            f"coordinates, solid) reaches it in {_count(policy, 'success')} and touches an obstacle in "
            f"{_count(policy, 'obstacle')}; the deployable one (/cmd_vel from odometry, IMU and scan, dotted) reaches it "
            f"in {_count(deploy, 'success')} and touches an obstacle in {_count(deploy, 'obstacle')}.")


DEPLOY = "deployable policy (SAC, /cmd_vel)"
DEPLOY_POLICY = "nav_deploy_atrvjr"
"""The shipped policy the nav picture draws as the deployable one: the ATRV-Jr's own, at its limits."""
"""The nav picture's label of the shipped ``nav_deploy`` policy."""


def provenance(*policies: Path) -> dict:
    """The picture's provenance, as ``benchmarks/_common`` records a results file's (taken before anything is written)."""
    return _common.figure_provenance(VERSION, script=__file__, task=True, policies=policies)


def _png(fig) -> bytes:
    import io

    buffer = io.BytesIO()
    fig.savefig(buffer, format="png")
    return buffer.getvalue()


def write_caption(out: Path, outcomes: dict[str, list[str]], seed: int, record: dict) -> None:
    """``out`` (JSON): the outcomes, the caption written from them, and the provenance ``record``."""
    import json

    out.write_text(json.dumps({"rule": f"the first {len(outcomes['nav policy (SAC)'])} episodes of the test set",
                               "seed": seed, "outcomes": outcomes, "caption": nav_caption(outcomes, seed),
                               "provenance": record}, indent=2) + "\n")


def draw_nav(out: Path, seed: int, episodes: int = 4) -> list[str]:
    """Scripted driver against the shipped navigation policies (torque and deployable) on the same four episodes; the
    caption beside it."""
    import matplotlib.pyplot as plt
    from matplotlib.patches import Circle, Polygon

    from atrv_warp import load_policy
    from atrv_warp.core.robot import robot_spec
    from atrv_warp.integrations.topdown import obstacle_shapes
    from atrv_warp.policy import policy_record, pretrained_nav_policy_path, shipped_policy_path
    from atrv_warp.task.baseline import scripted_policy

    record = provenance(pretrained_nav_policy_path(), shipped_policy_path(DEPLOY_POLICY))
    trained = policy_record(DEPLOY_POLICY)  # the task it trained on, at its robot's limits: not today's declaration
    runs = {"scripted driver": nav_paths(scripted_policy(), episodes, seed),
            "nav policy (SAC)": nav_paths(load_policy(pretrained_nav_policy_path()), episodes, seed),
            DEPLOY: nav_paths(load_policy(DEPLOY_POLICY), episodes, seed, task=trained.task,
                              robot=robot_spec(trained.robot))}
    fig, axes = plt.subplots(1, episodes, figsize=(4.0 * episodes, 4.3), dpi=90)
    base = runs["nav policy (SAC)"]
    for w, ax in enumerate(np.atleast_1d(axes)):
        start, target = base["paths"][0, w], base["target"][w]
        lo = np.minimum(start, target) - 3.0
        span = float((np.maximum(start, target) + 3.0 - lo).max())
        h = base["half"]
        ax.imshow(base["heights"][base["tile"][w]].T, origin="lower", extent=(-h, h, -h, h), cmap="gist_earth",
                  alpha=0.6)
        for kind, shape in obstacle_shapes(base["kind"][w], base["pose"][w], base["size"][w]):
            if kind == "cylinder":
                ax.add_patch(Circle(tuple(shape[:2]), shape[2], color="0.2"))
            else:
                ax.add_patch(Polygon(shape, closed=True, color="0.2"))
        ax.add_patch(Circle(tuple(target), base["reach"], color="tab:blue", alpha=0.35))
        for (name, run), (style, color) in zip(runs.items(), (("--", "tab:red"), ("-", "tab:orange"),
                                                               (":", "tab:purple"))):
            xy = run["paths"][:, w]
            ax.plot(xy[:, 0], xy[:, 1], style, lw=2, color=color, label=f"{name}: {run['reason'][w]}")
        ax.plot(*start, "o", color="k")
        ax.set_xlim(lo[0], lo[0] + span)
        ax.set_ylim(lo[1], lo[1] + span)
        ax.set_aspect("equal")
        ax.legend(loc="lower left", fontsize=7)
        ax.set_title(f"episode {w}", fontsize=9)
    fig.suptitle("navigation task: terrain (shaded by height), obstacles (dark), start (o), target (disc)",
                 fontsize=10)
    fig.tight_layout()
    _common.write_png_provenance(_png(fig), out, record)
    plt.close(fig)
    write_caption(out.with_suffix(".json"), {name: run["reason"] for name, run in runs.items()}, seed, record)
    return [f"{name}: {', '.join(run['reason'])}" for name, run in runs.items()]


def viewer_screenshot(out: Path, seed: int, episodes: int = 4) -> None:
    """Record the shipped nav policy's evaluation into a served viewer and photograph the page."""
    from atrv_warp import ATRVjrEnv, load_policy
    from atrv_warp.integrations.browser import capture_viewer
    from atrv_warp.integrations.recorder import RerunRecorder
    from atrv_warp.policy import pretrained_nav_policy_path
    from atrv_warp.task.evaluation import evaluate

    record = provenance(pretrained_nav_policy_path())
    env = ATRVjrEnv(episodes, task="nav")
    recorder = RerunRecorder(env.sim, serve=True, worlds=range(episodes))
    try:
        evaluate(load_policy(pretrained_nav_policy_path()), num_episodes=episodes, seed=seed, env=env,
                 on_step=recorder.env_hook())
        recorder.rec.flush()
        report = capture_viewer(recorder.viewer, out, size=(1400, 860), settle_s=90.0)
    finally:
        recorder.close()
    if not report.grpc_responses or report.errors:
        raise RuntimeError(f"the viewer did not load the recording: {report.errors or report.console[-5:]}")
    _common.write_png_provenance(out.read_bytes(), out, record)


def video_frame(out: Path, seed: int, episodes: int = 4, follow: float = 10.0, at: float = 0.3) -> str:
    """A frame of the evaluation video of four nav episodes of the shipped nav policy, each panel following
    its rover over ``follow`` metres, ``at`` of the way through the longest episode."""
    import io

    from PIL import Image

    from atrv_warp import ATRVjrEnv, load_policy
    from atrv_warp.integrations.video import EvalVideo
    from atrv_warp.policy import pretrained_nav_policy_path
    from atrv_warp.task.evaluation import evaluate

    record = provenance(pretrained_nav_policy_path())
    env = ATRVjrEnv(episodes, task="nav")
    video = EvalVideo(env, episodes=episodes, panel=320, follow=follow)
    evaluate(load_policy(pretrained_nav_policy_path()), num_episodes=episodes, seed=seed, env=env,
             on_step=video.env_hook())
    frames = list(video.frames())
    buffer = io.BytesIO()
    Image.fromarray(frames[int(at * (len(frames) - 1))]).save(buffer, format="png")
    _common.write_png_provenance(buffer.getvalue(), out, record)
    return ", ".join(video.reason)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=8)
    parser.add_argument("--seed", type=int, default=2024, help="the standard evaluation set's seed")
    parser.add_argument("--world", type=int, default=0, help="the episode to animate")
    parser.add_argument("--out-dir", default=str(DOCS))
    parser.add_argument("--viewer", action="store_true", help="also photograph the Rerun web viewer (Chromium)")
    parser.add_argument("--nav", action="store_true",
                        help="only the navigation task's pictures: docs/nav.png, docs/eval_video_frame.png "
                             "(and with --viewer, docs/viewer.png)")
    args = parser.parse_args()
    import matplotlib

    matplotlib.use("Agg")
    out = Path(args.out_dir)
    if args.nav:
        print("\n".join(draw_nav(out / "nav.png", args.seed)) + f"\nwrote {out / 'nav.png'} and {out / 'nav.json'}")
        print(f"{video_frame(out / 'eval_video_frame.png', args.seed)}\nwrote {out / 'eval_video_frame.png'}")
        if args.viewer:
            viewer_screenshot(out / "viewer.png", args.seed)
            print(f"wrote {out / 'viewer.png'}")
        return 0
    run = rollout(args.episodes, args.seed)
    draw_trajectories(run, out / "trajectories.png")
    draw_episode(run, args.world, out / "episode.gif")
    print(f"{', '.join(run['reason'])}\nwrote {out / 'trajectories.png'} and {out / 'episode.gif'}")
    if args.viewer:
        viewer_screenshot(out / "viewer.png", args.seed)
        print(f"wrote {out / 'viewer.png'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
