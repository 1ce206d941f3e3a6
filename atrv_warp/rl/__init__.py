"""Learning to drive with TorchRL SAC.

- :mod:`.config`: :class:`TrainConfig`, presets (``configs/*.toml``) and the command-line reader.
- :mod:`.loop`: :func:`train`, which reads top to bottom, and the loop it runs.
- :mod:`.collectors`: the collectors (``async``, ``sync``, ``ray``) behind one table.
- :mod:`.learner`: critics, the SAC-family loss, optimisers and the replay buffer.
- :mod:`.checkpoint`: :class:`RunState` and the checkpoint that saves and restores it.
- :mod:`.reporting`: progress bar, statistics, loggers and the learning curve.
- :mod:`.export`: a policy as a ``torch.export`` program (``.pt2``, with its contract), and as ONNX.

The actor and the saved-policy format live below training, in :mod:`atrv_warp.policy`.
"""
