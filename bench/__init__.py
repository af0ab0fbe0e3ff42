"""Benchmarks: `make bench` (python -m bench). Medians and ratios against peers in one run."""
