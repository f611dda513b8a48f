"""A pinhole camera: primary rays through pixel centres, projection, and EXR camera matrices.

Conventions (the same as ``svgf_cli.frame``): pixel ``(x, y)`` covers ``[x, x+1) x [y, y+1)``
with row 0 at the top and y growing down; the primary ray of a pixel goes through its centre
``(x + 0.5, y + 0.5)`` with no jitter, so the G-buffer is noise-free and consistent with the
motion vectors (SVGF assumes a rasterised G-buffer).

Camera space follows the OpenEXR ``worldToCamera`` definition: origin at the eye, +x right,
+y up, +z the viewing direction (a left-handed frame). NDC follows ``worldToNDC``: (0, 0) is
the top-left and (1, 1) the bottom-right corner of the image, after the divide by w.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

# The near distance only shapes NDC z (z_ndc = 1 - near / view_depth); x and y do not use it.
NDC_NEAR = 1e-3


def _normalize(v: np.ndarray) -> np.ndarray:
    length = float(np.linalg.norm(v))
    if not math.isfinite(length) or length == 0.0:
        raise ValueError(f"cannot normalise vector {v.tolist()}")
    return v / length


@dataclass(frozen=True)
class Camera:
    """A pinhole camera with a vertical field of view in degrees and square pixels."""

    position: np.ndarray
    look_at: np.ndarray
    up: np.ndarray
    fov_y: float
    width: int
    height: int

    @property
    def forward(self) -> np.ndarray:
        return _normalize(np.asarray(self.look_at, float) - np.asarray(self.position, float))

    def basis(self) -> np.ndarray:
        """Rows: right, up, forward (world space unit vectors)."""
        forward = self.forward
        right = _normalize(np.cross(forward, np.asarray(self.up, float)))
        true_up = np.cross(right, forward)
        return np.stack([right, true_up, forward])

    @property
    def tan_half_fov(self) -> tuple[float, float]:
        """(tan of half the horizontal fov, tan of half the vertical fov)."""
        tan_y = math.tan(math.radians(self.fov_y) * 0.5)
        return tan_y * self.width / self.height, tan_y

    def world_to_camera(self) -> np.ndarray:
        """4x4 column-vector matrix: world point -> camera space (x right, y up, z forward)."""
        rotation = self.basis()
        matrix = np.eye(4)
        matrix[:3, :3] = rotation
        matrix[:3, 3] = -rotation @ np.asarray(self.position, float)
        return matrix

    def camera_to_ndc(self) -> np.ndarray:
        """4x4 column-vector matrix: camera space -> homogeneous NDC (divide by w = depth)."""
        tan_x, tan_y = self.tan_half_fov
        return np.array(
            [
                [0.5 / tan_x, 0.0, 0.5, 0.0],
                [0.0, -0.5 / tan_y, 0.5, 0.0],
                [0.0, 0.0, 1.0, -NDC_NEAR],
                [0.0, 0.0, 1.0, 0.0],
            ]
        )

    def world_to_ndc(self) -> np.ndarray:
        return self.camera_to_ndc() @ self.world_to_camera()

    def exr_attributes(self) -> dict[str, np.ndarray]:
        """``worldToCamera``/``worldToNDC`` as OpenEXR stores them: Imath row-vector matrices
        (``p_row @ M``, translation in the last row), i.e. the transposes of ours."""
        return {
            "worldToCamera": self.world_to_camera().T.copy(),
            "worldToNDC": self.world_to_ndc().T.copy(),
        }

    def project(self, points: np.ndarray) -> np.ndarray:
        """World points ``(..., 3)`` -> continuous pixel coordinates ``(..., 2)`` (x right,
        y down, pixel centres at +0.5)."""
        m = self.world_to_ndc()
        p = np.asarray(points, dtype=np.float64)
        hom = p @ m[:, :3].T + m[:, 3]
        w = hom[..., 3]
        return np.stack([hom[..., 0] / w * self.width, hom[..., 1] / w * self.height], axis=-1)

    def view_depth(self, points: np.ndarray) -> np.ndarray:
        """Linear view depth: distance along the forward axis."""
        return (np.asarray(points, float) - np.asarray(self.position, float)) @ self.forward

    def primary_rays(self, jitter: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Unit directions ``(H*W, 3)`` float64 through every pixel centre, row-major from the
        top-left pixel, and the eye position ``(3,)``. With ``jitter`` ``(H, W, 2)`` in
        [0, 1) (x, y from the pixel's top-left corner) through those positions instead."""
        tan_x, tan_y = self.tan_half_fov
        right, up, forward = self.basis()
        if jitter is None:
            xs = ((np.arange(self.width) + 0.5) / self.width * 2.0 - 1.0) * tan_x
            ys = (1.0 - (np.arange(self.height) + 0.5) / self.height * 2.0) * tan_y
            # (H, 1, 3) + (1, W, 3): one row term and one column term per pixel.
            dirs = (ys[:, None, None] * up + forward)[:, :, :] + xs[None, :, None] * right
        else:
            x = (np.arange(self.width)[None, :] + jitter[..., 0]) / self.width
            y = (np.arange(self.height)[:, None] + jitter[..., 1]) / self.height
            dirs = (((1.0 - y * 2.0) * tan_y)[..., None] * up + forward
                    + ((x * 2.0 - 1.0) * tan_x)[..., None] * right)
        dirs = dirs.reshape(-1, 3)
        dirs /= np.sqrt(np.einsum("ij,ij->i", dirs, dirs))[:, None]
        return dirs, np.asarray(self.position, dtype=np.float64)


def default_camera(lo: np.ndarray, hi: np.ndarray, width: int, height: int) -> Camera:
    """A camera on the +z side of the bounds looking at their centre (-z), y up, 39.3 degrees
    vertical fov (the Cornell box camera's), far enough that the bounding sphere fits."""
    centre = (np.asarray(lo, float) + np.asarray(hi, float)) * 0.5
    radius = max(float(np.linalg.norm(np.asarray(hi, float) - lo)) * 0.5, 1e-6)
    fov_y = 39.3
    tan_y = math.tan(math.radians(fov_y) * 0.5)
    half_fov = math.atan(min(tan_y, tan_y * width / height))
    distance = radius / math.sin(half_fov)
    return Camera(
        position=centre + np.array([0.0, 0.0, distance]),
        look_at=centre,
        up=np.array([0.0, 1.0, 0.0]),
        fov_y=fov_y,
        width=width,
        height=height,
    )
