"""An Embree (embreex) path tracer that renders SVGF input sequences and their references.

Modules: ``scene`` (OBJ + MTL loading, materials), ``animation`` (camera, object and
emission keyframes), ``camera`` (pinhole camera, matrices, projection), ``bsdf`` (the
glossy GGX material), ``kernels`` (numba shading kernels), ``tracing`` (the wavefront
integrator and the G-buffer), ``gradients`` (A-SVGF temporal gradient samples), ``render``
(one frame's layers, radiance, gradient samples and reference), ``output`` (EXR channels
and header attributes in `svgf denoise`'s input convention).
User documentation: docs/trace.md.
"""

from __future__ import annotations
