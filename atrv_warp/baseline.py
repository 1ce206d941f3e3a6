"""The scripted baseline on the standard evaluation set: ``python -m atrv_warp.baseline [--task nav] [--json F]``.

The driver itself is :class:`atrv_warp.task.baseline.ScriptedDriver`.
"""

from __future__ import annotations

import argparse
import sys

__all__ = ["main"]


def main(argv: list[str] | None = None) -> int:
    from atrv_warp.task.baseline import scripted_policy
    from atrv_warp.task.evaluation import evaluate, format_result, write_result

    parser = argparse.ArgumentParser(prog="python -m atrv_warp.baseline", description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=1000)
    parser.add_argument("--seed", type=int, default=2024)
    parser.add_argument("--task", default="reach", help="task: reach | nav")
    parser.add_argument("--json", metavar="FILE", help="also write the figures to FILE")
    args = parser.parse_args(argv)
    from atrv_warp.task.config import TASK_VARIANTS

    if args.task not in TASK_VARIANTS:
        parser.error(f"unknown --task {args.task!r}; known: {sorted(TASK_VARIANTS)}")
    result = evaluate(scripted_policy(), num_episodes=args.episodes, seed=args.seed, task=args.task)
    name = f"scripted baseline ({args.task})"
    print(format_result(name, result))
    if args.json:
        write_result(args.json, name, args.task, args.seed, result)
    return 0


if __name__ == "__main__":
    sys.exit(main())
