"""Export a trained policy to a file that runs with torch alone: ``python -m atrv_warp.export [--onnx] [POLICY] OUT``.

POLICY is a ``best_policy.pt``, a training ``checkpoint.pt``, a shipped policy's name (``reach``, ``nav``,
``nav_plain``, ``nav_deploy``), or omitted for the ``reach`` policy shipped with the package; OUT ends in ``.pt2`` (a ``torch.export`` archive). See
:mod:`atrv_warp.rl.export` for what the file holds, and ``examples/run_exported_policy.py`` for a
standalone inference loop.

Examples::

    python -m atrv_warp.export policy.pt2                               # the shipped policy
    python -m atrv_warp.export runs/default/best_policy.pt my_rover.pt2
    python -m atrv_warp.export --onnx policy.pt2                        # also policy.onnx (extra: onnx)
    python -m atrv_warp.export nav nav.pt2                              # a shipped policy by name
"""

from __future__ import annotations

import argparse
import sys

from atrv_warp.runtime import error_line
from atrv_warp.storage import FileFormatError

__all__ = ["build_parser", "main"]


def build_parser() -> argparse.ArgumentParser:
    """The command line's parser (the docs' command table reads it too)."""
    parser = argparse.ArgumentParser(prog="python -m atrv_warp.export", description=__doc__.splitlines()[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter, epilog=__doc__)
    parser.add_argument("paths", nargs="+", metavar="[POLICY] OUT", help="policy file or a shipped policy's name (default: the shipped reach "
                        "policy), output .pt2")
    parser.add_argument("--onnx", action="store_true", help="also write OUT.onnx, checked with onnxruntime")
    parser.add_argument("--force", action="store_true", help="overwrite OUT (and OUT.onnx) where it exists")
    parser.add_argument("--task-module", metavar="FILE.py", default=None,
                        help="a Python file that registers the policy's task, a task of your own (never read from the "
                             "policy file: docs/your-own-task.md)")
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if len(args.paths) > 2:
        parser.error("expected [POLICY] OUT")
    policy, out = (None, args.paths[0]) if len(args.paths) == 1 else args.paths
    from atrv_warp.rl.export import export_policy, load_exported
    from atrv_warp.task.registry import load_task_module

    try:
        if args.task_module:
            load_task_module(args.task_module)
        path = export_policy(policy, out, onnx=args.onnx, force=args.force)
    except (FileNotFoundError, FileExistsError, FileFormatError, ValueError, RuntimeError) as err:
        return error_line(parser.prog, str(err))
    except ModuleNotFoundError as err:
        return error_line(parser.prog, f"--onnx needs the onnx extra ({err.name} is missing): pip install -e '.[onnx]'")
    _, spec = load_exported(path)
    action = spec["action"]
    columns = ", ".join(f"{n} x {k:g} {u}" for n, k, u in zip(action["names"], action["scale"], action["units"],
                                                               strict=True))
    print(f"wrote {path}: {spec['observation_kind']} observation ({len(spec['observation'])},) -> {action['kind']} "
          f"action (2,) in [-1, 1] ({columns}); runs with torch alone (atrv_warp.core.files.load_exported_program checks it, then torch.export.load)")
    robot = spec.get("robot")
    if robot:
        lim = robot["limits"]
        print(f"trained on {robot['name']} ({robot['title']}), whose limits are {lim['linear_velocity']:g} m/s and "
              f"{lim['angular_velocity']:g} rad/s; it controls at {spec['rate_hz']:.3g} Hz")
    if args.onnx:
        print(f"wrote {path.with_suffix('.onnx')}: checked with onnxruntime against the torch policy (< 1e-5)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
