"""An Embree (embreex) path tracer that renders SVGF input sequences and their references.

Modules: ``scene`` (OBJ + MTL loading), ``animation`` (camera and object keyframes),
``camera`` (pinhole camera, matrices, projection), ``kernels`` (numba shading kernels),
``render`` (the wavefront integrator and the per-frame layers), ``output`` (EXR channels
and header attributes in `svgf denoise`'s input convention).
"""

from __future__ import annotations
