"""The methods SVGF is compared with, each produced in memory from the noisy input sequence.

* ``oidn``: Intel Open Image Denoise (``pyoidn``), RT filter, one frame at a time, HDR colour
  with the albedo and normal as guides. No temporal reuse. The emission plane (when the input
  has one) is taken out before and added back after, as SVGF does. Where the G-buffer is
  noisy (a renderer's 1-spp AOVs: every ``--preset-aovs`` but ``svgf``) it runs the way
  Blender's Denoise node and OIDN's documentation do: the albedo and the normal are first
  denoised by their own RT filters (the *prefilter*), then the beauty with ``clean_aux``.
  ``svgf trace``'s G-buffer is noise-free, so there the aux goes in as it is (``clean_aux``).
* ``oidn-noprefilter``: the same with the aux always taken as clean (no prefilter), to show
  what the prefilter is worth on noisy-aux inputs.
* ``accumulate``: our SVGF pipeline with ``atrous_iterations=0``: plain exponential temporal
  accumulation through the motion vectors, no spatial filter.
* ``atrous``: our SVGF pipeline with ``temporal=False``: the edge-aware a-trous wavelet filter
  with spatial variance, every frame cold.
* ``forward``: our SVGF pipeline as given but causal (``bidirectional=False``);
* ``bidirectional``: the same with ``bidirectional=True``, run by the real file driver
  (``svgf_cli.run.bidirectional``: both passes, the forward state spilled to a scratch
  folder) into a temporary folder before scoring, then read back frame by frame. Together
  the two compare forward-only against bidirectional on any sequence, whichever the
  denoised files are.
* ``input``: the raw noisy radiance itself (not a baseline one chooses; added by ``--input``).

Every method turns one :class:`Frame` into one ``(3, H, W)`` float32 radiance image. The
stateful ones must see the frames in order.
"""

from __future__ import annotations

import io
import tempfile
from collections.abc import Sequence
from pathlib import Path
from typing import Protocol

import numpy as np

from svgf_cli.errors import UsageError
from svgf_cli.filters.params import SVGFParams
from svgf_cli.frame import Frame

BASELINES: tuple[str, ...] = (
    "oidn", "oidn-noprefilter", "accumulate", "atrous", "forward", "bidirectional",
)
OIDN_BASELINES = ("oidn", "oidn-noprefilter")
# Baselines that carry history: they must see every frame between the scored ones.
TEMPORAL_BASELINES = ("accumulate", "forward", "bidirectional")

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


def oidn_prefilters(layers: str) -> bool:
    """Whether the ``oidn`` baseline prefilters the aux of inputs read with ``layers``: the
    tracer's G-buffer (``svgf``) is noise-free, a renderer's 1-spp AOVs are not."""
    return layers != "svgf"


class OidnMethod:
    """Intel Open Image Denoise, RT filter, per frame, HDR colour + albedo + normal; with
    ``prefilter`` the albedo and normal are denoised first (OIDN's noisy-aux recipe)."""

    def __init__(self, quality: str = "high", prefilter: bool = False,
                 name: str = "oidn") -> None:
        self._pyoidn = import_pyoidn()
        self.quality = quality
        self.prefilter = prefilter
        self.name = name
        self._device = None

    def process(self, frame: Frame) -> np.ndarray:
        # OIDN wants (H, W, 3); HDR colour must be non-negative, albedo in [0, 1] and
        # normals in [-1, 1]. Directly seen emission is noise-free and OIDN, not told which
        # pixels are lights, smears them (measured on testdata/seq: 99.8 % of its squared
        # error sat on the light). Like SVGF, it denoises the rest and gets the emission
        # added back.
        radiance = noisy_radiance(frame)
        if frame.emission is not None:
            radiance = radiance - frame.emission
        color = _hwc(np.maximum(radiance, 0.0))
        albedo = _hwc(np.clip(frame.albedo, 0.0, 1.0))
        normal = _hwc(np.clip(frame.normal, -1.0, 1.0))
        if self.prefilter:
            albedo = np.clip(self._aux_filter("albedo", albedo), 0.0, 1.0)
            normal = np.clip(self._aux_filter("normal", normal), -1.0, 1.0)
        out = self._pyoidn.denoise(
            color, albedo, normal, hdr=True, clean_aux=True, quality=self.quality
        )
        result = np.moveaxis(np.asarray(out, dtype=np.float32), -1, 0)
        if frame.emission is not None:
            result = result + frame.emission
        return np.ascontiguousarray(result, dtype=np.float32)

    def _aux_filter(self, slot: str, image: np.ndarray) -> np.ndarray:
        """OIDN's prefilter: an RT filter given only the ``slot`` image (albedo or normal)
        writes its denoised version (OIDN README, "Denoising with prefiltering")."""
        oidn = self._pyoidn
        if self._device is None:
            self._device = oidn.Device(oidn.OIDN_DEVICE_TYPE_CPU)
            self._device.commit()
        output = np.zeros_like(image)
        flt = oidn.Filter(self._device, oidn.OIDN_FILTER_TYPE_RT)
        try:
            flt.set_image(slot, image, oidn.OIDN_FORMAT_FLOAT3)
            flt.set_image(oidn.OIDN_IMAGE_OUTPUT, output, oidn.OIDN_FORMAT_FLOAT3)
            flt.set_int("quality", _QUALITY[self.quality])
            flt.commit()
            flt.execute()
        finally:
            flt.release()
        error = self._device.get_error()
        if error:
            raise RuntimeError(f"OIDN {slot} prefilter failed: {error}")
        return output


_QUALITY = {"default": 0, "fast": 4, "balanced": 5, "high": 6}


def _hwc(planes: np.ndarray) -> np.ndarray:
    """(3, H, W) -> contiguous float32 (H, W, 3), the layout OIDN reads."""
    return np.ascontiguousarray(np.moveaxis(planes, 0, -1), dtype=np.float32)


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
        return params.replace(atrous_iterations=0, feedback_iteration=-1, bidirectional=False)
    if name == "atrous":
        return params.replace(temporal=False, bidirectional=False)
    if name == "forward":
        return params.replace(bidirectional=False)
    if name == "bidirectional":
        return params.replace(bidirectional=True)
    raise ValueError(f"{name!r} is not an SVGF-derived baseline")


class BidirectionalMethod:
    """SVGF with ``bidirectional=True`` over the whole input sequence, run up front by the
    file driver into a temporary folder (float colour only); :meth:`process` returns the
    next frame's output. The folder is removed by :meth:`close` or at exit."""

    name = "bidirectional"

    def __init__(self, params: SVGFParams, inputs: Sequence[tuple[int, Path]],
                 layers: str) -> None:
        from svgf_cli.io.exr import read_rgb
        from svgf_cli.io.layers import build_mapping
        from svgf_cli.progress import Progress
        from svgf_cli.run.chunk import run_sequence
        from svgf_cli.run.tasks import FrameTask, RunConfig

        self._folder = tempfile.TemporaryDirectory(prefix="svgf-evaluate-")
        self._read = read_rgb
        mapping = build_mapping(layers)
        self._mapping = mapping
        self._outputs = [Path(self._folder.name) / f"o.{f}.exr" for f, _ in inputs]
        tasks = [FrameTask(f, path, out) for (f, path), out in
                 zip(inputs, self._outputs, strict=True)]
        config = RunConfig(params=baseline_params("bidirectional", params), preset="evaluate",
                           mapping=mapping, float_colour=True, colour_only=True)
        quiet = Progress("lines", 0, quiet=True, out=io.StringIO(), err=io.StringIO())
        quiet.show_progress = False
        run_sequence(tasks, config, quiet)
        self._next = 0

    def process(self, frame: Frame) -> np.ndarray:
        image, _ = self._read(self._outputs[self._next], self._mapping)
        self._next += 1
        return np.ascontiguousarray(image, dtype=np.float32)

    def close(self) -> None:
        self._folder.cleanup()


def make_method(name: str, params: SVGFParams,
                inputs: Sequence[tuple[int, Path]] | None = None,
                layers: str = "svgf") -> Method:
    """A fresh method instance for one pass over a sequence (``inputs``, the frames it is
    fed with their files, and the AOV preset ``layers``: for ``bidirectional``)."""
    if name == "oidn":
        return OidnMethod(prefilter=oidn_prefilters(layers))
    if name == "oidn-noprefilter":
        return OidnMethod(prefilter=False, name=name)
    if name in ("accumulate", "atrous", "forward"):
        return DenoiserMethod(name, baseline_params(name, params))
    if name == "bidirectional":
        if inputs is None:
            raise UsageError("--baseline bidirectional needs the input frames (--input)")
        return BidirectionalMethod(params, inputs, layers)
    if name == "input":
        return InputMethod()
    raise UsageError(f"unknown baseline {name!r} (choose from {', '.join(BASELINES)})")
