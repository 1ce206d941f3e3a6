"""Learning to drive with TorchRL SAC.

- :mod:`.config`: :class:`TrainConfig` and its groups, and :func:`to_toml`.
- :mod:`.command_line`: the command line and the presets (``configs/*.toml``) and files it reads.
- :mod:`.loop`: :func:`train`, which reads top to bottom, and the loop it runs.
- :mod:`.collectors`: the collectors (``async``, ``sync``, ``ray``) behind one table.
- :mod:`.learner`: critics, the SAC-family loss, optimisers and the replay buffer.
- :mod:`.checkpoint`: :class:`RunState` and the checkpoint that saves and restores it.
- :mod:`.reporting`: progress bar, statistics, loggers and the learning curve.
- :mod:`.export`: a policy as a ``torch.export`` program (``.pt2``, with its contract), and as ONNX.

The actor and the saved-policy format live below training, in :mod:`atrv_warp.policy`.
"""
