"""An exported policy as a ROS 2 node a rover runs: ``python -m atrv_warp.deploy POLICY.pt2`` (``atrv-deploy``).

At run time it needs torch, rclpy and the message packages only: no Warp, Newton, TorchRL or anything of the
simulator (``tests/test_deploy.py`` imports it in a fresh interpreter and checks), so it installs on a robot alone
(``deploy/pyproject.toml``, the ``atrv-deploy`` distribution; docs/deploy.md).

- :mod:`.contract`: the policy file and its contract (:func:`~.contract.load_deployable`); :mod:`.messages`: the robot's
  messages read; :mod:`.controller`: each control period's decision (:class:`~.controller.Controller`); torch and
  :mod:`atrv_warp.core` only;
- :mod:`.parameters`: the node's parameters; :mod:`.node`: the rclpy node; :mod:`.cli`: the command line.
"""

from atrv_warp.deploy.cli import build_parser, main

__all__ = ["build_parser", "main"]
