"""The drive-to-target task on the simulator.

- :mod:`.spec`: the task's contract, declared once (observation, end reasons, reward terms, actions).
- :mod:`.config`: :class:`TaskConfig`, the task's numbers.
- :mod:`.kernels`: observation, reward terms, termination and reset sampling as Warp kernels.
- :mod:`.env`: :class:`RoverEnv`, the TorchRL environment; :class:`EnvFactory` for workers.
- :mod:`.baseline`: the scripted driver; :mod:`.evaluation`: seeded evaluation of any policy.
"""
