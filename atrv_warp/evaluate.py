"""Evaluate a saved policy on seeded episodes: ``python -m atrv_warp.evaluate [CHECKPOINT]``.

CHECKPOINT is a ``best_policy.pt``, a training ``checkpoint.pt``, or omitted for the policy
shipped with the package. Reports success rate, mean return, mean steps and the failure
breakdown (wall, flip, timeout), optionally as JSON.

Examples::

    python -m atrv_warp.evaluate                          # the shipped policy, 1000 episodes
    python -m atrv_warp.evaluate runs/default/best_policy.pt --episodes 200 --seed 7
    python -m atrv_warp.evaluate --baseline               # the scripted driver, for comparison (atrv-baseline)
    python -m atrv_warp.evaluate --task nav               # the shipped navigation policy
    python -m atrv_warp.evaluate nav_plain                # a shipped policy by name (atrv_warp.policy.SHIPPED_POLICIES)
    python -m atrv_warp.evaluate --task nav --randomization wide   # under shift: per-world physics, noise, latency
    python -m atrv_warp.evaluate --task nav --baseline --episodes 8 --rerun nav.rrd
    python -m atrv_warp.evaluate --episodes 8 --rerun eval.rrd      # record 4 worlds; view: rerun eval.rrd
    python -m atrv_warp.evaluate --episodes 4 --serve --real-time   # live web viewer on 127.0.0.1
    python -m atrv_warp.evaluate --task nav --episodes 64 --video nav.mp4   # the first 4 episodes, top down
    python -m atrv_warp.evaluate --task nav --episodes 4 --video nav.mp4 --video-follow 10   # a camera on each rover
"""

from __future__ import annotations

import argparse
import sys

from atrv_warp.runtime import add_verbose_argument, device_summary, error_line, set_verbose

__all__ = ["baseline_main", "build_parser", "main"]


def build_parser() -> argparse.ArgumentParser:
    """The command line's parser (the docs' command table reads it too)."""
    parser = argparse.ArgumentParser(prog="python -m atrv_warp.evaluate", description=__doc__.splitlines()[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter, epilog=__doc__)
    parser.add_argument("checkpoint", nargs="?", default=None, help="policy or checkpoint file, or a shipped policy's name (reach, nav, nav_plain, nav_deploy; "
                             "default: the task's shipped one)")
    parser.add_argument("--episodes", type=int, default=1000, help="number of seeded episodes (one world each)")
    parser.add_argument("--seed", type=int, default=None, help="evaluation-set seed (default: the standard set)")
    parser.add_argument("--baseline", action="store_true", help="evaluate the scripted baseline instead")
    parser.add_argument("--task", default=None,
                        help="task: reach | nav | nav_deploy (default: the policy's own; reach for the baseline)")
    parser.add_argument("--randomization", default="none", metavar="PRESET",
                        help="evaluate under domain randomization: none | mild | wide (each world draws its physics, "
                             "sensor noise and latency from the evaluation seed); prints success by parameter bin")
    parser.add_argument("--sim-config", metavar="FILE",
                        help="simulator-config TOML, e.g. atrv-calibrate's fit of a real rover (docs/calibration.md)")
    parser.add_argument("--device", default="cpu", help="simulation device")
    parser.add_argument("--json", metavar="FILE", help="also write the figures to FILE")
    parser.add_argument("--rerun", metavar="FILE.rrd", help="record the episodes to a Rerun file")
    parser.add_argument("--serve", action="store_true", help="serve a live Rerun web viewer on 127.0.0.1")
    parser.add_argument("--real-time", action="store_true", help="slow the simulation to real time")
    parser.add_argument("--worlds", type=int, nargs="+", default=None,
                        help="worlds (episodes) to record (default: the first 4)")
    parser.add_argument("--video", metavar="FILE.mp4", help="draw the first episodes top down into an MP4")
    parser.add_argument("--video-episodes", type=int, default=4, help="episodes in the video (default: 4)")
    parser.add_argument("--video-follow", type=float, default=None, metavar="METRES",
                        help="each panel follows its rover over this much ground (default: the whole arena)")
    add_verbose_argument(parser)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.episodes < 1:
        parser.error("--episodes must be >= 1")
    if args.video_episodes < 1:
        parser.error("--video-episodes must be >= 1")
    if args.video_follow is not None and not args.video_follow > 0:
        parser.error("--video-follow must be > 0 metres")
    if args.video:
        from atrv_warp.integrations.video import check_video_path

        try:  # its folder is created now, before any work; a path that cannot be written stops here
            check_video_path(args.video)
        except ValueError as err:
            return error_line(parser.prog, f"--{err}")
    if args.rerun:
        from atrv_warp.integrations.recorder import check_recording_path

        try:  # as --video: a recording that cannot be written stops here, before the simulator is built
            check_recording_path(args.rerun)
        except ValueError as err:
            return error_line(parser.prog, f"--rerun: {err}")
    if args.verbose:
        set_verbose()
    from atrv_warp.task.config import TASK_VARIANTS
    from atrv_warp.task.evaluation import (
        EVAL_SEED,
        format_bins,
        format_result,
        run_episodes,
        success_by_bin,
        write_result,
    )

    if args.task is not None and args.task not in TASK_VARIANTS:
        return error_line(parser.prog, f"unknown --task {args.task!r}; known: {sorted(TASK_VARIANTS)}")
    from atrv_warp.task.randomization import get_randomization

    try:
        randomization = get_randomization(args.randomization)
    except ValueError as err:
        return error_line(parser.prog, f"--randomization: {err}")
    task = args.task or "reach"
    if args.baseline:
        from atrv_warp.task.baseline import scripted_policy

        policy, name = scripted_policy(), f"scripted baseline ({task})"
    else:
        from atrv_warp.policy import SHIPPED_POLICIES, load_policy, policy_task
        from atrv_warp.storage import FileFormatError

        # no file: the policy shipped for the task (a registered name, resolved by load_policy)
        path = args.checkpoint or (args.task if args.task in SHIPPED_POLICIES else "reach")
        try:
            trained_on = policy_task(path)
            # a policy that commands or observes another kind than the task's is refused first, naming both
            policy = load_policy(path, task=args.task or trained_on)
            if args.task is not None and args.task != trained_on:
                return error_line(parser.prog, f"{path} was trained on task {trained_on!r}, not {args.task!r}")
        except (FileNotFoundError, FileFormatError, ValueError) as err:
            return error_line(parser.prog, f"cannot load policy: {err}")
        task, name = trained_on, path
    try:
        print(device_summary(args.device))
    except (RuntimeError, ValueError) as err:
        return error_line(parser.prog, f"--device {args.device!r}: {err}")
    seed = EVAL_SEED if args.seed is None else args.seed
    if args.sim_config:
        from atrv_warp.sim.config import load_sim_config

        try:
            load_sim_config(args.sim_config)
        except ValueError as err:
            return error_line(parser.prog, f"--sim-config: {err}")
    from atrv_warp.task.env import ATRVjrEnv

    recorder, on_step, video = None, None, None
    env = ATRVjrEnv(args.episodes, device=args.device, task=task, randomization=randomization,
                    sim_config=args.sim_config)
    policy = policy.to(env.device)  # loaded on the CPU; the env's observations live on its device
    if args.rerun or args.serve or args.real_time:
        from atrv_warp.integrations.recorder import RerunRecorder

        recorder = RerunRecorder(env.sim, path=args.rerun, serve=args.serve, worlds=args.worlds,
                                 real_time=args.real_time)
        on_step = recorder.env_hook()
    if args.video:
        from atrv_warp.integrations.video import EvalVideo

        video = EvalVideo(env, episodes=args.video_episodes, follow=args.video_follow)
        draw, rerun_step = video.env_hook(), on_step
        on_step = draw if rerun_step is None else (lambda e, td: (rerun_step(e, td), draw(e, td)))
    try:
        record = run_episodes(policy, env, seed=seed, on_step=on_step)
    finally:
        if recorder is not None:
            recorder.close()
    result = record.summary()
    extra = {}
    print(format_result(name, result) + (f" | randomization {args.randomization}" if randomization.enabled else ""))
    if randomization.enabled:
        table = success_by_bin(record)
        print(format_bins(table))
        extra = {"randomization": args.randomization, "success_by_bin": table}
    if args.rerun:
        print(f"recording: {args.rerun}  (view with: rerun {args.rerun})")
    if video is not None:
        written = video.write(args.video)
        print(f"video: {written.path} ({written.frames} frames, {written.width}x{written.height}, "
              f"{len(video.worlds)} episodes; drawn and encoded in {written.render_s:.2f} s)")
    if args.serve and sys.stdin.isatty():
        input("viewer running; press Enter to stop ...")
    if args.json:
        write_result(args.json, name, task, seed, result, **extra)
    return 0


def baseline_main(argv: list[str] | None = None) -> int:
    """``atrv-baseline [--task nav] [--json F] …``: ``evaluate --baseline``, the scripted driver on the
    standard evaluation set."""
    return main(["--baseline", *(sys.argv[1:] if argv is None else argv)])


if __name__ == "__main__":
    sys.exit(main())
