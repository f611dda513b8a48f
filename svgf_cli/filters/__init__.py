"""SVGF stages as plain array kernels; knows arrays, nothing about files."""
