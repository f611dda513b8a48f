"""The typed frame that flows from I/O into the filters: structure-of-arrays float32 planes.

Conventions (every producer converts to these, every consumer relies on them):

* colour-like planes are ``(3, H, W)`` float32, C-contiguous, one plane per channel;
* row 0 is the top of the image, x grows right, y grows down;
* ``depth`` is linear view depth, ``(H, W)``; a value ``<= 0`` marks background
  (readers map non-finite or non-positive input depth to 0);
* ``motion`` is ``(2, H, W)`` backward motion in pixels: the surface seen at pixel centre
  ``(x + 0.5, y + 0.5)`` was at ``(x + 0.5 + motion[0], y + 0.5 + motion[1])`` in the
  previous frame;
* ``mesh_id`` is ``(H, W)`` int32, ``-1`` on background;
* ``direct``/``indirect`` are the two noisy signals; when both are absent ``color`` is the
  single combined signal. ``emission`` (optional) is radiance emitted at the primary hit.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


def _check_plane(name: str, plane: np.ndarray, shape: tuple[int, ...], dtype: type) -> None:
    if plane.shape != shape:
        raise ValueError(f"{name}: expected shape {shape}, got {plane.shape}")
    if plane.dtype != dtype:
        raise ValueError(f"{name}: expected dtype {np.dtype(dtype)}, got {plane.dtype}")
    if not plane.flags.c_contiguous:
        raise ValueError(f"{name}: planes must be C-contiguous")


@dataclass
class Frame:
    """One input frame: noisy radiance signals plus the noise-free G-buffer."""

    albedo: np.ndarray
    normal: np.ndarray
    depth: np.ndarray
    motion: np.ndarray
    mesh_id: np.ndarray
    direct: np.ndarray | None = None
    indirect: np.ndarray | None = None
    color: np.ndarray | None = None
    emission: np.ndarray | None = None

    @property
    def height(self) -> int:
        return int(self.depth.shape[0])

    @property
    def width(self) -> int:
        return int(self.depth.shape[1])

    @property
    def split(self) -> bool:
        """True when direct and indirect are filtered as two separate signals."""
        return self.direct is not None and self.indirect is not None

    def signals(self) -> list[tuple[str, np.ndarray]]:
        """The radiance signals to filter, by name: ``direct`` + ``indirect`` or ``color``."""
        if self.split:
            assert self.direct is not None and self.indirect is not None
            return [("direct", self.direct), ("indirect", self.indirect)]
        if self.color is None:
            raise ValueError("frame has neither direct+indirect nor color")
        return [("color", self.color)]

    def validate(self) -> None:
        """Raise ValueError when a plane has the wrong shape, dtype or layout."""
        h, w = self.depth.shape
        f32 = np.float32
        _check_plane("depth", self.depth, (h, w), f32)
        _check_plane("albedo", self.albedo, (3, h, w), f32)
        _check_plane("normal", self.normal, (3, h, w), f32)
        _check_plane("motion", self.motion, (2, h, w), f32)
        _check_plane("mesh_id", self.mesh_id, (h, w), np.int32)
        for name in ("direct", "indirect", "color", "emission"):
            plane = getattr(self, name)
            if plane is not None:
                _check_plane(name, plane, (3, h, w), f32)
        if (self.direct is None) != (self.indirect is None):
            raise ValueError("direct and indirect must be given together")
        if not self.split and self.color is None:
            raise ValueError("frame has neither direct+indirect nor color")


@dataclass
class DenoisedFrame:
    """What the denoiser returns for one frame.

    ``color`` is the final ``(3, H, W)`` radiance (remodulated, emission added, signals
    summed). ``layers`` holds optional debug planes keyed by EXR channel name, each
    ``(H, W)`` float32 (e.g. ``variance.direct``, ``history_length``, ``direct.R``).
    """

    color: np.ndarray
    layers: dict[str, np.ndarray]
