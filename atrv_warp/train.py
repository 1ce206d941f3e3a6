"""Train a driver with TorchRL SAC: ``python -m atrv_warp.train``.

Usage::

    python -m atrv_warp.train                                  # preset "default" (the TrainConfig defaults)
    python -m atrv_warp.train --config smoke                   # preset "smoke": seconds, once compiled
    python -m atrv_warp.train --config my_run.toml             # your own TOML file
    python -m atrv_warp.train num_envs=128 max_minutes=5       # override any field by its name
    python -m atrv_warp.train --env.num-envs 128               # ... or by its group (--help lists them)
    python -m atrv_warp.train --resume runs/default            # continue a killed run

Outputs in ``<out_dir>/<name>/``: ``config.toml`` (resolved), ``checkpoint.pt`` (atomic,
at every evaluation), ``best_policy.pt`` (best periodic evaluation), ``final_eval.json``,
``logs/`` (CSV or TensorBoard scalars), ``learning_curve.png``.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from atrv_warp.rl.config import TrainConfig, cli_args, load_train_config, preset_names
from atrv_warp.rl.loop import train
from atrv_warp.runtime import add_verbose_argument, error_line, set_verbose
from atrv_warp.storage import FileFormatError

__all__ = ["main"]

DEFAULT_PRESET = "default"
PROG = "python -m atrv_warp.train"


def _parse(argv: list[str]) -> tuple[argparse.Namespace, list[str]]:
    """Our own options; the rest is the configuration's command line (tyro's)."""
    parser = argparse.ArgumentParser(prog=PROG, add_help=False,
                                     formatter_class=argparse.RawDescriptionHelpFormatter, epilog=__doc__)
    parser.add_argument("-h", "--help", action="store_true", help="this help, then every configuration field")
    parser.add_argument("--config", default=None, metavar="PRESET|FILE",
                        help=f"a preset shipped with the package ({', '.join(preset_names())}; default "
                             f"{DEFAULT_PRESET!r}) or a TOML file")
    parser.add_argument("--resume", metavar="RUN_DIR", default=None, help="continue the run in RUN_DIR")
    add_verbose_argument(parser)
    args, rest = parser.parse_known_args(argv)
    if args.help:
        print(parser.format_help())
    return args, rest


def _configure(args: argparse.Namespace, rest: list[str]) -> TrainConfig:
    """Defaults, then the preset / file (or the resumed run's config.toml), then the command line.
    A bad key or value is a ValueError; tyro exits with status 2 on a malformed argument."""
    import tyro

    if args.resume:
        run_dir = Path(args.resume)
        cfg_file = run_dir / "config.toml"
        if not cfg_file.is_file():
            raise FileNotFoundError(f"--resume: {cfg_file} not found")
        base = load_train_config(str(cfg_file), {"out_dir": str(run_dir.parent), "name": run_dir.name})
    else:
        base = load_train_config(args.config or DEFAULT_PRESET)
    tokens = ["--help"] if args.help else cli_args(rest)
    cfg = tyro.cli(TrainConfig, default=base, args=tokens, prog=PROG, config=(tyro.conf.FlagConversionOff,),
                   description="Configuration fields: --group.field VALUE, or field=VALUE.")
    return cfg.validate()


def main(argv: list[str] | None = None) -> int:
    args, rest = _parse(sys.argv[1:] if argv is None else argv)
    if args.verbose:
        set_verbose()
    try:
        cfg = _configure(args, rest)
    except (ValueError, FileNotFoundError) as err:
        return error_line(PROG, str(err))
    try:
        train(cfg, resume=bool(args.resume))
    except (FileExistsError, FileNotFoundError, ModuleNotFoundError, FileFormatError) as err:
        return error_line(PROG, str(err))
    return 0


if __name__ == "__main__":
    sys.exit(main())
