"""Print the rover model as the reference does: ``python -m atrv_warp.model [--robot NAME] [--urdf PATH] [--variant NAME]``.

The body tree (body, parent, joint type) and the body table (joint type, degrees of freedom).
"""

from __future__ import annotations

import argparse
import sys

from atrv_warp.sim.config import nominal_rover_config, replace_checked
from atrv_warp.sim.model import format_table, format_tree
from atrv_warp.sim.urdf import load_rover

__all__ = ["build_parser", "main"]


def build_parser() -> argparse.ArgumentParser:
    """The command line's parser (the docs' command table reads it too)."""
    parser = argparse.ArgumentParser(prog="python -m atrv_warp.model", description=__doc__.splitlines()[0])
    parser.add_argument("--robot", help="a shipped robot's name (atrvjr, jackal, husky) or a robot file's path "
                                        "(default: the ATRV-Jr)")
    parser.add_argument("--urdf", help="URDF file (default: the robot's)")
    parser.add_argument("--variant", default="realistic", help="ATRV-Jr variant: realistic | reference")
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        rover = nominal_rover_config(args.robot, args.variant)
        if args.urdf:
            rover = replace_checked(rover, urdf=args.urdf)
        desc = load_rover(rover)
    except ValueError as err:  # RobotFileError, URDFError
        print(f"error: {err}", file=sys.stderr)
        return 2
    print(f"{desc.name}  ({desc.path})\n")
    print(format_tree(desc))
    print()
    print(format_table(desc))
    return 0


if __name__ == "__main__":
    sys.exit(main())
