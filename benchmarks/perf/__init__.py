"""The perf benchmarks (``python -m benchmarks.perf.NAME --help``)."""
