"""The training benchmarks (``python -m benchmarks.training.NAME --help``)."""
