"""The physics benchmarks (``python -m benchmarks.physics.NAME --help``)."""
