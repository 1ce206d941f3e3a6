"""The benchmark scripts, one package: each runs from the repository's root as ``python -m benchmarks.<topic>.<name>``
and writes a results file under ``benchmarks/results/`` with its provenance (:mod:`benchmarks._common`). The topics:
``perf`` (speed and cost), ``physics``, ``robots``, ``calibration``, ``transfer`` (the MuJoCo twin and the deploy
checks) and ``training``."""
