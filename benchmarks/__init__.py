"""Benchmarks: each times its subject against an anchor in the same run. Run each from the repository root as a
module, e.g. ``python -m benchmarks.core_speed --json out/core_speed.json``."""
