"""Benchmark scripts (run each as ``python benchmarks/<name>.py``); not part of the package."""
