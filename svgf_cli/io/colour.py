"""Luminance weights of a file's RGB primaries (the EXR ``chromaticities`` attribute).

The filters weight R, G and B into a luminance for their edge-stopping and variance terms.
Those weights are the Y row of the RGB -> CIE XYZ matrix of the file's primaries and white
point: Rec.709 / sRGB (0.2126, 0.7152, 0.0722) when the attribute is absent, as OpenEXR
specifies, and e.g. (0.2722, 0.6741, 0.0537) for ACEScg (AP1).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

# OpenEXR's default when a file has no chromaticities attribute: Rec.709 primaries, D65.
REC709_CHROMATICITIES = (0.64, 0.33, 0.30, 0.60, 0.15, 0.06, 0.3127, 0.3290)


@dataclass(frozen=True)
class LuminanceWeights:
    """(wr, wg, wb) summing to 1, and where they came from (for logs and `svgf inspect`)."""

    weights: tuple[float, float, float]
    source: str  # "chromaticities attribute", "Rec.709 (no chromaticities)", ...

    def non_negative(self) -> tuple[float, float, float]:
        """The weights with negatives set to 0 and renormalised to sum 1, for code that
        needs a non-negative luminance (AP0's blue weight is -0.0721)."""
        clipped = [max(w, 0.0) for w in self.weights]
        total = sum(clipped)
        r, g, b = (w / total for w in clipped)
        return (r, g, b)

    def for_filter(self) -> tuple[float, float, float]:
        """The weights the filter uses (``Frame.luminance_weights``): these weights, or
        :meth:`non_negative` where one is negative (a negative weight would make a bright
        saturated colour read as negative luminance, which the filter's luminance terms
        cannot take)."""
        if min(self.weights) >= 0.0:
            return self.weights
        return self.non_negative()

    def describe(self) -> str:
        r, g, b = self.weights
        text = f"luminance weights R {r:.4f}, G {g:.4f}, B {b:.4f} ({self.source})"
        if self.for_filter() != self.weights:
            r, g, b = self.for_filter()
            text += f"; the filter uses R {r:.4f}, G {g:.4f}, B {b:.4f} (negative set to 0)"
        return text


def rgb_to_xyz_matrix(chromaticities: Sequence[float]) -> np.ndarray:
    """The 3x3 RGB -> XYZ matrix (float64) of primaries and white point given as
    ``(rx, ry, gx, gy, bx, by, wx, wy)``, normalised so that white has Y = 1.

    Columns are the XYZ of each primary, ``(x, y, 1 - x - y)`` scaled by ``S``, where
    ``S`` solves ``P S = W`` for the white point ``W = (wx/wy, 1, (1 - wx - wy)/wy)``. Working
    with ``(x, y, z)`` rather than ``(x/y, 1, z/y)`` keeps primaries with ``y = 0`` (the
    XYZ "primaries" of an XYZ-encoded file) finite. Raises ValueError when degenerate.
    """
    values = np.asarray(chromaticities, dtype=np.float64)
    if values.shape != (8,) or not np.isfinite(values).all():
        raise ValueError("chromaticities must be 8 finite numbers")
    xy = values.reshape(4, 2)
    wx, wy = xy[3]
    if wy <= 0:
        raise ValueError("white point has y <= 0")
    primaries = np.stack([xy[:3, 0], xy[:3, 1], 1.0 - xy[:3, 0] - xy[:3, 1]])  # columns
    white = np.array([wx / wy, 1.0, (1.0 - wx - wy) / wy])
    if abs(np.linalg.det(primaries)) < 1e-9:
        raise ValueError("primaries are collinear")
    scale = np.linalg.solve(primaries, white)
    return primaries * scale[None, :]


def luminance_weights(chromaticities: Sequence[float] | None) -> LuminanceWeights:
    """Luminance weights for a file's ``chromaticities`` (None: absent, Rec.709).

    Degenerate values (non-finite, collinear primaries, a white point with y <= 0) fall back to
    Rec.709, and ``source`` says so: a broken attribute must not break the filter.
    """
    if chromaticities is None:
        return LuminanceWeights(_y_row(REC709_CHROMATICITIES), "Rec.709, no chromaticities")
    try:
        weights = _y_row(chromaticities)
    except ValueError as exc:
        return LuminanceWeights(
            _y_row(REC709_CHROMATICITIES), f"Rec.709: chromaticities attribute unusable, {exc}"
        )
    return LuminanceWeights(weights, f"from chromaticities {_name(chromaticities)}")


def _y_row(chromaticities: Sequence[float]) -> tuple[float, float, float]:
    # Not clamped at 0: AP0 (ACES2065-1) really has a negative blue weight (-0.0721).
    row = rgb_to_xyz_matrix(chromaticities)[1]
    if not np.isfinite(row).all() or abs(row.sum() - 1.0) > 1e-6 or row.max() <= 0:
        raise ValueError(f"implausible luminance row {row.round(4).tolist()}")
    r, g, b = (float(v) for v in row)
    return (r, g, b)


# Named primaries, for a readable log line only (the weights come from the numbers).
_KNOWN = {
    "Rec.709/sRGB": REC709_CHROMATICITIES,
    "ACEScg (AP1)": (0.713, 0.293, 0.165, 0.830, 0.128, 0.044, 0.32168, 0.33767),
    "ACES2065-1 (AP0)": (0.7347, 0.2653, 0.0, 1.0, 0.0001, -0.077, 0.32168, 0.33767),
    "Rec.2020": (0.708, 0.292, 0.170, 0.797, 0.131, 0.046, 0.3127, 0.3290),
    "DCI-P3 D65": (0.680, 0.320, 0.265, 0.690, 0.150, 0.060, 0.3127, 0.3290),
    "CIE XYZ": (1.0, 0.0, 0.0, 1.0, 0.0, 0.0, 1.0 / 3.0, 1.0 / 3.0),
}


def _name(chromaticities: Sequence[float]) -> str:
    values = np.asarray(chromaticities, dtype=np.float64)
    for name, known in _KNOWN.items():
        if np.allclose(values, known, atol=5e-4):
            return name
    return "(" + ", ".join(f"{v:.4g}" for v in values) + ")"
