"""The robots benchmarks (``python -m benchmarks.robots.NAME --help``)."""
