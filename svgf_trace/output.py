"""Turn a rendered frame into EXR channels in `svgf denoise`'s input convention."""

from __future__ import annotations

from typing import Any

import numpy as np

from svgf_cli import __version__
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


def input_channels(
    result: FrameResult, *, half_radiance: bool = True
) -> tuple[dict[str, np.ndarray], dict[str, bool]]:
    """Channels and per-channel half flags for one noisy input frame.

    ``R,G,B`` is computed as ``direct + indirect`` from the values as stored (rounded to half
    first when radiance is half), so a reader adding the two layers gets the combined layer
    back exactly with ``--float`` and to within half rounding otherwise.
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
    channels.update(_split("emission", emission, RGB))
    radiance = set(channels)
    channels.update(_split("albedo", result.layers["albedo"], RGB))
    channels.update(_split("N", result.layers["N"], XYZ))
    channels["Z"] = result.layers["Z"]
    channels.update(_split("P", result.layers["P"], XYZ))
    channels.update(_split("motion", result.layers["motion"], ("X", "Y")))
    channels["id"] = result.layers["id"]
    half = {name: half_radiance and name in radiance for name in channels}
    return channels, half


def reference_channels(result: FrameResult) -> dict[str, np.ndarray]:
    """Converged ``R,G,B`` (= direct + indirect), ``direct.*`` and ``indirect.*``, float."""
    channels: dict[str, np.ndarray] = {}
    channels.update(_split("", result.direct + result.indirect, RGB))
    channels.update(_split("direct", result.direct, RGB))
    channels.update(_split("indirect", result.indirect, RGB))
    return channels


def frame_attributes(
    result: FrameResult, *, frame: int, spp: int, seed: int, max_depth: int, kind: str
) -> dict[str, Any]:
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
    return attributes
