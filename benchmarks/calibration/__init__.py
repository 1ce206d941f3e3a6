"""The calibration benchmarks (``python -m benchmarks.calibration.NAME --help``)."""
