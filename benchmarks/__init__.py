"""Benchmark and study scripts (run as ``python benchmarks/NAME.py``); a package so tests import their logic by name."""
