"""The transfer benchmarks (``python -m benchmarks.transfer.NAME --help``)."""
