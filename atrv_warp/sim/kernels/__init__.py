"""Warp kernels, grouped by family: ``contact`` (Hunt–Crossley forces against the arena)
and ``rover`` (wheel drive, derived per-world state, masked resets)."""
