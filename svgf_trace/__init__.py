"""An Embree (embreex) path tracer that renders SVGF input sequences and their references.

Modules: ``scene`` (OBJ + MTL loading, materials), ``animation`` (camera, object and
emission keyframes), ``camera`` (pinhole camera, matrices, projection), ``bsdf`` (the
glossy GGX material), ``kernels`` (numba shading kernels), ``render`` (the wavefront
integrator and the per-frame layers), ``gradients`` (A-SVGF temporal gradient samples),
``output`` (EXR channels and header attributes in `svgf denoise`'s input convention).
User documentation: docs/trace.md.
"""

from __future__ import annotations
