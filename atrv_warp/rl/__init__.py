"""Learning to drive with TorchRL SAC.

- :mod:`.config`: :class:`TrainConfig`, presets (``configs/*.toml``) and the override reader.
- :mod:`.agents`: actor and critics with built-in observation normalisation; saved policies.
- :mod:`.trainer`: :func:`train` from small factories (collector, buffer, learner, loggers).
"""
