"""The command-line tools, one module each: thin wrappers over library functions, each installed by
``pyproject.toml``'s ``[project.scripts]``.

- :mod:`.train` (``atrv-train``): train a driver with SAC or PPO;
- :mod:`.evaluate` (``atrv-evaluate``, ``atrv-baseline``): evaluate a saved policy, or the scripted driver;
- :mod:`.demo` (``atrv-demo``): drive five ways side by side;
- :mod:`.model` (``atrv-model``): print the rover model;
- :mod:`.export` (``atrv-export``): export a policy to a file that runs with torch alone;
- :mod:`.calibrate` (``atrv-calibrate``): fit the simulator to a drive recorded on a rover (:mod:`atrv_warp.sim.sysid`);
- :mod:`.robot` (``atrv-robot``): list, start, check and measure robot files;
- :mod:`.ros` (``atrv-ros``): the simulator as a ROS 2 node (:mod:`atrv_warp.integrations.ros`).

``atrv-deploy``, the exported policy as a ROS 2 node on the robot, lives in :mod:`atrv_warp.deploy.cli`: the deploy
package runs with torch and ROS 2 alone and ships by itself (the slim ``atrv-deploy`` wheel), so its command stays
with it.

Each command also runs as ``python -m atrv_warp.<command>`` (the module ``atrv_warp.<command>`` re-exports it), or
``python -m atrv_warp.cli.<command>``. This package imports none of them: a command loads only what it needs.
"""
