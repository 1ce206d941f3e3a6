"""Evaluate a saved policy on seeded episodes: ``python -m atrv_warp.evaluate [CHECKPOINT]``.

The command lives in :mod:`atrv_warp.cli.evaluate`; this module keeps ``python -m atrv_warp.evaluate`` and
``from atrv_warp.evaluate import main`` working.
"""

import sys

from atrv_warp.cli.evaluate import (
    ENGINES,
    MUJOCO_EXTRA,  # noqa: F401 - public before the move, not in __all__
    Evaluation,
    baseline_main,
    build_parser,
    evaluate_around,
    evaluate_policy,
    main,
)

__all__ = ["ENGINES", "Evaluation", "baseline_main", "build_parser", "evaluate_around", "evaluate_policy", "main"]

if __name__ == "__main__":
    sys.exit(main())
