"""What an evaluation video costs a training run: ``python -m benchmarks.perf.video_cost [--rounds 3]``.

For each task, with its shipped policy on the periodic evaluation's set (256 episodes, seed 2024,
the trainer's ``Evaluator`` environment): the evaluation alone, the evaluation while
:class:`~atrv_warp.integrations.video.EvalVideo` records the first ``video_episodes`` worlds
(its ``env_hook``), then drawing and encoding the MP4, and the GIF that TensorBoard gets on top.
Rounds are interleaved; the median of each is kept. One core, one torch thread: the trainer's.
The recorded episodes are checked (every one ended) and the file decoded back before any time
counts. Prints the table and writes ``benchmarks/results/video_cost.json``.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

from benchmarks._common import load_results, markdown_table, pin_to_one_core, write_results

VERSION = 1
"""This script's method, bumped by hand when what it measures or how changes (``_common.write_results``)."""

RESULTS = Path(__file__).resolve().parents[1] / "results"
ROOT = Path(__file__).resolve().parents[2]


def measure(task: str, rounds: int, episodes: int, video_episodes: int, out_dir: Path) -> dict:
    import torch

    from atrv_warp.integrations.video import EvalVideo, read_video
    from atrv_warp.policy import load_policy, pretrained_nav_policy_path, pretrained_policy_path
    from atrv_warp.task.env import ATRVjrEnv
    from atrv_warp.task.evaluation import EVAL_SEED, evaluate

    torch.set_num_threads(1)
    policy = load_policy(pretrained_nav_policy_path() if task == "nav" else pretrained_policy_path())
    env = ATRVjrEnv(episodes, task=task, seed=EVAL_SEED)
    video = EvalVideo(env, episodes=video_episodes)
    evaluate(policy, num_episodes=episodes, env=env, on_step=video.env_hook())  # warm-up: kernels, encoder
    written = video.write(out_dir / f"{task}.mp4", gif=True)
    assert all(video.reason), f"{task}: a recorded episode did not end: {video.reason}"
    assert read_video(written.path) == (written.frames, written.width, written.height), "the video does not decode"
    times = {"evaluation_s": [], "evaluation_recording_s": [], "mp4_s": [], "mp4_and_gif_s": []}
    for _ in range(rounds):
        t0 = time.perf_counter()
        evaluate(policy, num_episodes=episodes, env=env)
        times["evaluation_s"].append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        evaluate(policy, num_episodes=episodes, env=env, on_step=video.env_hook())
        times["evaluation_recording_s"].append(time.perf_counter() - t0)
        times["mp4_s"].append(video.write(out_dir / f"{task}.mp4").render_s)
        times["mp4_and_gif_s"].append(video.write(out_dir / f"{task}.mp4", gif=True).render_s)
    med = {k: statistics.median(v) for k, v in times.items()}
    recording = med["evaluation_recording_s"] - med["evaluation_s"]
    return {"task": task, "episodes": episodes, "video_episodes": video_episodes, "steps_recorded": video.steps,
            "frames": written.frames, "width": written.width, "height": written.height, "fps": written.fps,
            "mp4_bytes": written.path.stat().st_size, "gif_bytes": len(written.gif), "rounds": times, "median": med,
            "recording_s": recording, "video_s": recording + med["mp4_s"],
            "video_share_of_evaluation": (recording + med["mp4_s"]) / med["evaluation_s"]}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--episodes", type=int, default=256, help="evaluation episodes (logging.eval_episodes)")
    parser.add_argument("--video-episodes", type=int, default=4, help="logging.video_episodes")
    parser.add_argument("--tasks", nargs="+", default=["reach", "nav"])
    parser.add_argument("--out", default=str(RESULTS / "video_cost.json"))
    args = parser.parse_args()
    pin_to_one_core()
    with tempfile.TemporaryDirectory() as tmp:
        rows = [measure(task, args.rounds, args.episodes, args.video_episodes, Path(tmp)) for task in args.tasks]
    print("| task | evaluation [s] | recording [s] | MP4 [s] | + GIF [s] | video / evaluation | frames | MP4 |\n"
          "|---|---:|---:|---:|---:|---:|---:|---:|")
    for r in rows:
        m = r["median"]
        print(f"| {r['task']} | {m['evaluation_s']:.2f} | {r['recording_s']:.2f} | {m['mp4_s']:.2f} | "
              f"{m['mp4_and_gif_s'] - m['mp4_s']:.2f} | {100 * r['video_share_of_evaluation']:.0f} % | "
              f"{r['frames']} ({r['width']}x{r['height']}) | {r['mp4_bytes'] / 1e6:.2f} MB |")
    out = write_results(args.out, {"benchmark": "video_cost", "rows": rows, "time": time.strftime("%Y-%m-%d %H:%M:%S")}, version=VERSION, task=True)
    print(f"written to {out}")
    return 0


# --- the figures' tables, drawn from the results files at docs build time --------------------------

def video_cost() -> str:
    """``video_cost.json``: what an evaluation video costs, per task."""
    rows = []
    for r in load_results("video_cost.json")["rows"]:
        m = r["median"]
        rows.append([r["task"], f"{m['evaluation_s']:.2f} s", f"{r['recording_s']:.2f} s", f"{m['mp4_s']:.2f} s",
                     f"{m['mp4_and_gif_s'] - m['mp4_s']:.2f} s", f"{100 * r['video_share_of_evaluation']:.0f} %",
                     f"{r['frames']} ({r['width']}×{r['height']}, {r['fps']:g} fps)", f"{r['mp4_bytes'] / 1e6:.2f} MB"])
    return markdown_table(["task", "evaluation (256 episodes)", "recording", "drawing + MP4", "+ GIF (TensorBoard)",
                   "video / evaluation", "frames", "MP4"], ["---"] + ["---:"] * 7, rows)


TABLES = {
    "video_cost": video_cost,
}


if __name__ == "__main__":
    sys.exit(main())
