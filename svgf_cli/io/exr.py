"""OpenEXR reading and writing through OpenImageIO. Knows files and channels, not filtering."""

from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import OpenImageIO as oiio

from svgf_cli.errors import SvgfError


class ExrWriteError(SvgfError):
    """An output could not be written (nothing is left behind under the final name)."""


def temporary_path(path: Path) -> Path:
    """Hidden sibling name used while writing; renamed onto ``path`` once complete.

    It keeps the ``.exr`` extension so OpenImageIO picks the EXR writer, and starts with a
    dot so a half-written file never matches a frame pattern.
    """
    return path.with_name(f".{path.name}.{os.getpid()}.tmp.exr")


def write_exr(
    path: str | os.PathLike[str],
    channels: Mapping[str, np.ndarray],
    *,
    attributes: Mapping[str, Any] | None = None,
    half: Mapping[str, bool] | bool = False,
    compression: str = "zip",
) -> None:
    """Write ``channels`` (name -> (H, W) plane) to one EXR part, atomically.

    ``half`` is either one flag for all channels or a per-channel mapping (missing names are
    float). Attributes are passed through as header attributes; values OpenImageIO cannot
    store are skipped. The file is written to a temporary name and renamed, so the final name
    only ever holds a complete file; every OpenImageIO return value is checked.
    """
    path = Path(path)
    names = list(channels)
    if not names:
        raise ExrWriteError("no channels to write", str(path))
    planes = [np.asarray(channels[n], dtype=np.float32) for n in names]
    h, w = planes[0].shape
    for n, p in zip(names, planes, strict=True):
        if p.shape != (h, w):
            raise ExrWriteError(f"channel {n} has shape {p.shape}, expected {(h, w)}", str(path))
    # One contiguous (H, W, C) float32 buffer: OpenImageIO silently writes a header-only
    # file for non-contiguous arrays, so never hand it a view.
    pixels = np.ascontiguousarray(np.stack(planes, axis=-1), dtype=np.float32)

    def is_half(name: str) -> bool:
        return bool(half) if isinstance(half, bool) else bool(half.get(name, False))

    formats = [oiio.TypeDesc("half") if is_half(n) else oiio.TypeDesc("float") for n in names]
    spec = oiio.ImageSpec(w, h, len(names), oiio.TypeDesc("float"))
    spec.channelnames = tuple(names)
    spec.channelformats = tuple(formats)
    spec.attribute("compression", compression)
    for key, value in (attributes or {}).items():
        _set_attribute(spec, key, value)

    tmp = temporary_path(path)
    out = oiio.ImageOutput.create(str(tmp))
    if out is None:
        raise ExrWriteError(f"cannot create EXR writer: {oiio.geterror()}", str(path))
    try:
        if not out.open(str(tmp), spec):
            raise ExrWriteError(f"cannot open for writing: {out.geterror()}", str(path))
        if not out.write_image(pixels):
            raise ExrWriteError(f"write failed: {out.geterror()}", str(path))
        if not out.close():
            raise ExrWriteError(f"close failed: {out.geterror()}", str(path))
        os.replace(tmp, path)
    except BaseException:
        try:
            out.close()
        finally:
            tmp.unlink(missing_ok=True)
        raise


def _set_attribute(spec: oiio.ImageSpec, key: str, value: Any) -> None:
    """Set one header attribute, choosing the EXR type from the Python value."""
    if isinstance(value, bool):
        spec.attribute(key, int(value))
    elif isinstance(value, (int, np.integer)):
        spec.attribute(key, int(value))
    elif isinstance(value, (float, np.floating)):
        spec.attribute(key, float(value))
    elif isinstance(value, str):
        spec.attribute(key, value)
    elif isinstance(value, np.ndarray) and value.shape == (4, 4):
        spec.attribute(key, oiio.TypeDesc("matrix"), tuple(float(v) for v in value.ravel()))
    elif isinstance(value, (tuple, list)) and len(value) == 16:
        spec.attribute(key, oiio.TypeDesc("matrix"), tuple(float(v) for v in value))
    else:
        # Anything else (already-typed OIIO values from a passthrough) as its repr-free str.
        try:
            spec.attribute(key, value)
        except Exception:  # noqa: BLE001 - an attribute we cannot carry is dropped, not fatal
            pass
