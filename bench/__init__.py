"""Benchmarks (`make bench`): each module prints a table; figures are kept in BENCHMARKS.md."""
