"""Sinks and stored data: recordings (zarr)."""
