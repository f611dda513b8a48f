"""Render-farm support: chunk plans, progress reporting and the Dask backend."""
