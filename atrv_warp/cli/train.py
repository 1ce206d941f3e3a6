"""Train a driver with TorchRL SAC or PPO: ``python -m atrv_warp.train``.

Usage::

    python -m atrv_warp.train                                  # preset "default" (the TrainConfig defaults)
    python -m atrv_warp.train --config smoke                   # preset "smoke": seconds, once compiled
    python -m atrv_warp.train --config my_run.toml             # your own TOML file
    python -m atrv_warp.train num_envs=128 max_minutes=5       # override any field by its name
    python -m atrv_warp.train --env.num-envs 128               # ... or by its group (--help lists them)
    python -m atrv_warp.train --resume runs/default            # continue a killed run
    python -m atrv_warp.train --sim-config calibrated.toml randomization=around   # around a calibrated rover

Outputs in ``<out_dir>/<name>/``: ``config.toml`` (resolved), ``randomization.json`` (the ranges the envs draw
from, ``randomization=around`` resolved against ``--sim-config``), ``checkpoint.pt`` and ``save/`` (one whole
save at every evaluation: a kill at any instant resumes from the last with ``--resume``), ``best_policy.pt`` (best
periodic evaluation), ``final_eval.json``, ``logs/`` (CSV or TensorBoard scalars), ``learning_curve.png``.
"""

from __future__ import annotations

import sys

from atrv_warp.core.files import OutputPathError
from atrv_warp.rl.checkpoint import RunMismatch
from atrv_warp.rl.command_line import PROG, parse_command
from atrv_warp.rl.loop import train
from atrv_warp.runtime import error_line, set_verbose
from atrv_warp.storage import FileFormatError

__all__ = ["main"]


def main(argv: list[str] | None = None) -> int:
    try:
        cmd = parse_command(sys.argv[1:] if argv is None else argv)  # --help prints and exits here
    except (ValueError, FileNotFoundError) as err:
        return error_line(PROG, str(err))
    if cmd.verbose:
        set_verbose()
    try:
        train(cmd.train, resume=cmd.resume is not None)
    except (FileExistsError, FileNotFoundError, ModuleNotFoundError, FileFormatError, OutputPathError,
            RunMismatch) as err:
        return error_line(PROG, str(err))
    return 0


if __name__ == "__main__":
    sys.exit(main())
