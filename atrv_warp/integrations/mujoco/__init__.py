"""A MuJoCo twin of the nav world, for sim-to-sim: our deployable policy on another engine's contact, friction and
ray casting, through the observation code a robot runs (the ``mujoco`` extra: ``pip install 'atrv_warp[mujoco]'``).

- :mod:`.mjcf`: the world's MJCF, written from our descriptions (URDF, ``RoverDescription``, ``HeightGrid``,
  each episode's obstacles, the arena, the substep), and MuJoCo's contact settings (:class:`~.mjcf.MujocoContact`,
  the tyre's compliance);
- :mod:`.twin`: :class:`~.twin.MujocoTwin`, one rover stepped at the control period with our motor driver's loop,
  MuJoCo's rays for the scanner, the IMU and the wheel odometry;
- :mod:`.episodes`: our evaluation episodes in the twin (:func:`~.episodes.draw_episodes`,
  :func:`~.episodes.run_twin_episodes`) and :class:`~.episodes.DeployablePolicy`;
- :mod:`.record`: a calibration bag recorded from the twin (:func:`~.record.record_twin_bag`), for fitting our
  simulator to another engine's contact.

``python -m atrv_warp.evaluate --engine mujoco`` runs it, ``atrv-calibrate --record-example OUT --engine mujoco``
records it; ``benchmarks/transfer/mujoco_agreement.py`` compares its physics
with ours and ``benchmarks/transfer/mujoco_transfer.py`` measures the transfer (docs/physics.md).
"""

from __future__ import annotations

from .episodes import DeployablePolicy, TwinEpisode, TwinEpisodes, draw_episodes, run_twin_episode, run_twin_episodes
from .mjcf import MUJOCO_DEFAULT_CONTACT, MujocoContact, Obstacle, world_xml
from .twin import MujocoTwin

__all__ = ["MUJOCO_DEFAULT_CONTACT", "DeployablePolicy", "MujocoContact", "MujocoTwin", "Obstacle", "TwinEpisode",
           "TwinEpisodes", "draw_episodes", "run_twin_episode", "run_twin_episodes", "world_xml"]
