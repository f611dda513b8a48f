"""The methods SVGF is compared with, each produced in memory from the noisy input sequence.

* ``oidn``: Intel Open Image Denoise (``pyoidn``), RT filter, one frame at a time, HDR colour
  with the noise-free albedo and normal as guides (``clean_aux``). No temporal reuse. The
  emission plane (when the input has one) is taken out before and added back after, as SVGF
  does.
* ``accumulate``: our SVGF pipeline with ``atrous_iterations=0``: plain exponential temporal
  accumulation through the motion vectors, no spatial filter.
* ``atrous``: our SVGF pipeline with ``temporal=False``: the edge-aware a-trous wavelet filter
  with spatial variance, every frame cold.
* ``input``: the raw noisy radiance itself (not a baseline one chooses; added by ``--input``).

Every method turns one :class:`Frame` into one ``(3, H, W)`` float32 radiance image. The
stateful ones must see the frames in order.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np

from svgf_cli.errors import UsageError
from svgf_cli.filters.params import SVGFParams
from svgf_cli.frame import Frame

BASELINES: tuple[str, ...] = ("oidn", "accumulate", "atrous")

OIDN_MISSING = (
    "--baseline oidn needs Intel Open Image Denoise for Python: pip install 'svgf[oidn]' "
    "(package pyoidn)"
)


class Method(Protocol):
    """Something that turns the next input frame into a radiance image."""

    name: str

    def process(self, frame: Frame) -> np.ndarray: ...


def noisy_radiance(frame: Frame) -> np.ndarray:
    """The frame's unfiltered radiance, composed the way the denoiser composes its output:
    the sum of the signals plus the emission."""
    return frame.total_radiance()


class InputMethod:
    """The raw noisy input, scored as if it were a denoiser's output."""

    name = "input"

    def process(self, frame: Frame) -> np.ndarray:
        return noisy_radiance(frame)


class DenoiserMethod:
    """Our SVGF pipeline with modified parameters (one instance per sequence: it keeps history)."""

    def __init__(self, name: str, params: SVGFParams) -> None:
        from svgf_cli.filters.denoiser import Denoiser  # deferred: numba JIT on first use

        self.name = name
        self.params = params
        self._denoiser = Denoiser(params)

    def process(self, frame: Frame) -> np.ndarray:
        return np.ascontiguousarray(self._denoiser.process(frame).color, dtype=np.float32)


class OidnMethod:
    """Intel Open Image Denoise, RT filter, per frame, HDR colour + clean albedo + normal."""

    name = "oidn"

    def __init__(self, quality: str = "high") -> None:
        self._pyoidn = import_pyoidn()
        self.quality = quality

    def process(self, frame: Frame) -> np.ndarray:
        # OIDN wants (H, W, 3); HDR colour must be non-negative, albedo in [0, 1] and
        # normals in [-1, 1]. The G-buffer comes from noise-free primary hits: clean_aux.
        # Directly seen emission is noise-free too and OIDN, not told which pixels are
        # lights, smears them (measured on testdata/seq: 99.8 % of its squared error sat on
        # the light). Like SVGF, it denoises the rest and gets the emission added back.
        radiance = noisy_radiance(frame)
        if frame.emission is not None:
            radiance = radiance - frame.emission
        color = np.ascontiguousarray(np.moveaxis(np.maximum(radiance, 0.0), 0, -1))
        albedo = np.ascontiguousarray(np.moveaxis(np.clip(frame.albedo, 0.0, 1.0), 0, -1))
        normal = np.ascontiguousarray(np.moveaxis(np.clip(frame.normal, -1.0, 1.0), 0, -1))
        out = self._pyoidn.denoise(
            color, albedo, normal, hdr=True, clean_aux=True, quality=self.quality
        )
        result = np.moveaxis(np.asarray(out, dtype=np.float32), -1, 0)
        if frame.emission is not None:
            result = result + frame.emission
        return np.ascontiguousarray(result, dtype=np.float32)


def import_pyoidn():  # noqa: ANN201 - returns the optional module
    """``pyoidn``, or a UsageError (exit 2) with the install command when it is missing."""
    try:
        import pyoidn
    except ImportError as exc:
        raise UsageError(OIDN_MISSING) from exc
    return pyoidn


def baseline_params(name: str, params: SVGFParams) -> SVGFParams:
    """The SVGF parameters a denoiser baseline runs with, derived from the user's ``params``."""
    if name == "accumulate":
        # No spatial filter at all; the history is therefore the unfiltered accumulation.
        return params.replace(atrous_iterations=0, feedback_iteration=-1)
    if name == "atrous":
        return params.replace(temporal=False)
    raise ValueError(f"{name!r} is not an SVGF-derived baseline")


def make_method(name: str, params: SVGFParams) -> Method:
    """A fresh method instance for one pass over a sequence."""
    if name == "oidn":
        return OidnMethod()
    if name in ("accumulate", "atrous"):
        return DenoiserMethod(name, baseline_params(name, params))
    if name == "input":
        return InputMethod()
    raise UsageError(f"unknown baseline {name!r} (choose from {', '.join(BASELINES)})")
