"""The scripted baseline on the standard evaluation set: ``python -m atrv_warp.baseline``.

The driver itself is :class:`atrv_warp.task.baseline.ScriptedDriver`.
"""

from __future__ import annotations

import argparse
import sys

__all__ = ["main"]


def main(argv: list[str] | None = None) -> int:
    from atrv_warp.task.baseline import scripted_policy
    from atrv_warp.task.evaluation import evaluate, format_result

    parser = argparse.ArgumentParser(prog="python -m atrv_warp.baseline", description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=1000)
    parser.add_argument("--seed", type=int, default=2024)
    args = parser.parse_args(argv)
    result = evaluate(scripted_policy(), num_episodes=args.episodes, seed=args.seed)
    print(format_result("scripted baseline", result))
    return 0


if __name__ == "__main__":
    sys.exit(main())
