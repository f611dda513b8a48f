"""svgf: batch Spatiotemporal Variance-Guided Filtering for OpenEXR sequences."""

__version__ = "0.1.0"
