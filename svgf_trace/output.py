"""Turn a rendered frame into EXR channels in `svgf denoise`'s input convention."""

from __future__ import annotations

from typing import Any

import numpy as np

from svgf_cli import __version__
from svgf_trace.gradients import STRATUM
from svgf_trace.render import FrameResult

MOTION_CONVENTION = "backward-pixels"
RGB = ("R", "G", "B")
XYZ = ("X", "Y", "Z")


def _split(prefix: str, image: np.ndarray, names: tuple[str, ...]) -> dict[str, np.ndarray]:
    sep = "." if prefix else ""
    return {
        f"{prefix}{sep}{name}": np.ascontiguousarray(image[:, :, k], dtype=np.float32)
        for k, name in enumerate(names)
    }


def _as_half(image: np.ndarray) -> np.ndarray:
    return image.astype(np.float16).astype(np.float32)


LOBE_PASSES = ("DiffDir", "DiffInd", "GlossDir", "GlossInd")
# Layers that may be left out of input files (``svgf trace --skip-layer``): none of them is
# needed by ``svgf denoise``.
OPTIONAL_LAYERS = ("P", "emission", "id")


def _demodulated(radiance: np.ndarray, colour: np.ndarray) -> np.ndarray:
    """radiance / colour per channel, 0 where the colour is 0 (Cycles' light passes)."""
    safe = np.where(colour > 0.0, colour, 1.0)
    return np.where(colour > 0.0, radiance / safe, 0.0).astype(np.float32)


def lobe_channels(result: FrameResult) -> dict[str, np.ndarray]:
    """``DiffDir/DiffInd/DiffCol/GlossDir/GlossInd/GlossCol`` ``(H, W, 3)`` float32, in
    Blender Cycles' convention: ``Dir``/``Ind`` are the lobe's radiance divided by its
    ``Col`` as stored (float32), so ``sum (Dir + Ind) x Col + emission = R,G,B``."""
    assert result.lobes is not None
    diff_col = result.layers["DiffCol"]
    gloss_col = result.layers["GlossCol"]
    return {
        "DiffDir": _demodulated(result.lobes[:, :, 0], diff_col),
        "DiffInd": _demodulated(result.lobes[:, :, 1], diff_col),
        "DiffCol": diff_col,
        "GlossDir": _demodulated(result.lobes[:, :, 2], gloss_col),
        "GlossInd": _demodulated(result.lobes[:, :, 3], gloss_col),
        "GlossCol": gloss_col,
    }


def input_channels(
    result: FrameResult, *, half_radiance: bool = True, skip: tuple[str, ...] = ()
) -> tuple[dict[str, np.ndarray], dict[str, bool]]:
    """Channels and per-channel half flags for one noisy input frame.

    ``R,G,B`` is computed as ``direct + indirect`` from the values as stored (rounded to half
    first when radiance is half), so a reader adding the two layers gets the combined layer
    back exactly with ``--float`` and to within half rounding otherwise. Lobe passes,
    ``motion_next`` and ``gradient.*`` are written when the result has them; layers named in
    ``skip`` (``OPTIONAL_LAYERS``) are left out.
    """
    direct = result.direct
    indirect = result.indirect
    emission = result.layers["emission"]
    if half_radiance:
        direct, indirect, emission = _as_half(direct), _as_half(indirect), _as_half(emission)
    combined = direct + indirect  # float32 + float32, as a reader would add them
    channels: dict[str, np.ndarray] = {}
    channels.update(_split("", combined, RGB))
    channels.update(_split("direct", direct, RGB))
    channels.update(_split("indirect", indirect, RGB))
    if "emission" not in skip:
        channels.update(_split("emission", emission, RGB))
    if result.lobes is not None:
        for name, image in lobe_channels(result).items():
            channels.update(_split(name, image, RGB))
    colours = {f"{name}.{c}" for name in ("DiffCol", "GlossCol") for c in RGB}
    radiance = set(channels) - colours
    channels.update(_split("albedo", result.layers["albedo"], RGB))
    channels.update(_split("N", result.layers["N"], XYZ))
    channels["Z"] = result.layers["Z"]
    if "P" not in skip:
        channels.update(_split("P", result.layers["P"], XYZ))
    channels.update(_split("motion", result.layers["motion"], ("X", "Y")))
    if "motion_next" in result.layers:
        channels.update(_split("motion_next", result.layers["motion_next"], ("X", "Y")))
    if "id" not in skip:
        channels["id"] = result.layers["id"]
    if result.gradient is not None:
        for name, plane in result.gradient.items():
            channels[f"gradient.{name}"] = np.ascontiguousarray(plane, dtype=np.float32)
    half = {name: half_radiance and name in radiance for name in channels}
    return channels, half


def reference_channels(result: FrameResult, *, rgb_only: bool = False) -> dict[str, np.ndarray]:
    """Converged ``R,G,B`` (= direct + indirect), ``direct.*`` and ``indirect.*`` (only
    ``R,G,B`` with ``rgb_only``)."""
    channels: dict[str, np.ndarray] = {}
    channels.update(_split("", result.direct + result.indirect, RGB))
    if not rgb_only:
        channels.update(_split("direct", result.direct, RGB))
        channels.update(_split("indirect", result.indirect, RGB))
    return channels


def input_attributes(
    *, lobes: bool, motion_next: bool, gradient_samples: bool
) -> dict[str, Any]:
    """Header attributes that describe the optional layers of input frames."""
    attributes: dict[str, Any] = {}
    if lobes:
        attributes["svgf/lobes"] = "cycles"
    if motion_next:
        attributes["svgf/motion_next_convention"] = "forward-pixels"
    if gradient_samples:
        attributes["svgf/gradient/stratum"] = STRATUM
        attributes["svgf/gradient/luminance"] = "rec709"
    return attributes


def frame_attributes(
    result: FrameResult, *, frame: int, spp: int, seed: int, max_depth: int, kind: str,
    extra: dict[str, Any] | None = None,
) -> dict[str, Any]:  # fmt: skip
    """Header attributes: camera matrices (OpenEXR/Imath row-vector convention) plus
    ``svgf/*`` provenance."""
    attributes: dict[str, Any] = dict(result.camera.exr_attributes())
    attributes.update(
        {
            "svgf/spp": int(spp),
            "svgf/seed": int(seed),
            "svgf/frame": int(frame),
            "svgf/max_depth": int(max_depth),
            "svgf/kind": kind,
            "svgf/motion_convention": MOTION_CONVENTION,
            "svgf/camera/fov_y": float(result.camera.fov_y),
            "Software": f"svgf {__version__} trace",
        }
    )
    attributes.update(extra or {})
    return attributes
