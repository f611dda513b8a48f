"""Luminance weights from the EXR chromaticities attribute (Y row of RGB -> XYZ)."""

from __future__ import annotations

import numpy as np
import pytest

from svgf_cli.io.colour import REC709_CHROMATICITIES, luminance_weights, rgb_to_xyz_matrix

ACESCG = (0.713, 0.293, 0.165, 0.830, 0.128, 0.044, 0.32168, 0.33767)
REC2020 = (0.708, 0.292, 0.170, 0.797, 0.131, 0.046, 0.3127, 0.3290)
AP0 = (0.7347, 0.2653, 0.0, 1.0, 0.0001, -0.077, 0.32168, 0.33767)
P3_D65 = (0.680, 0.320, 0.265, 0.690, 0.150, 0.060, 0.3127, 0.3290)  # SMPTE EG 432-1
XYZ = (1.0, 0.0, 0.0, 1.0, 0.0, 0.0, 1 / 3, 1 / 3)
PROPHOTO = (0.7347, 0.2653, 0.1596, 0.8404, 0.0366, 0.0001, 0.3457, 0.3585)  # ROMM RGB, D50


@pytest.mark.parametrize(
    ("chromaticities", "expected"),
    [
        (REC709_CHROMATICITIES, (0.2126, 0.7152, 0.0722)),  # ITU-R BT.709 / sRGB
        (ACESCG, (0.2722, 0.6741, 0.0537)),  # ACES TB-2014-004 (AP1)
        (REC2020, (0.2627, 0.6780, 0.0593)),  # ITU-R BT.2020
        (AP0, (0.3440, 0.7282, -0.0721)),  # ACES2065-1: a negative blue weight, kept
        (P3_D65, (0.2290, 0.6917, 0.0793)),  # Display P3 / P3-D65
        (PROPHOTO, (0.2880, 0.7119, 0.0001)),  # ISO 22028-2 (ROMM RGB)
    ],
)
def test_published_luminance_rows(chromaticities, expected) -> None:
    weights = luminance_weights(chromaticities)
    assert np.allclose(weights.weights, expected, atol=1e-4)
    assert abs(sum(weights.weights) - 1.0) < 1e-9
    assert "from chromaticities" in weights.source


def test_matrix_maps_white_to_y_one_and_primaries_to_their_chromaticity() -> None:
    matrix = rgb_to_xyz_matrix(ACESCG)
    white = matrix @ np.ones(3)
    assert np.isclose(white[1], 1.0)
    assert np.allclose(white[:2] / white.sum(), ACESCG[6:])
    for column, (x, y) in zip(matrix.T, np.reshape(ACESCG[:6], (3, 2)), strict=True):
        assert np.allclose(column[:2] / column.sum(), (x, y))


def test_absent_and_broken_attributes_fall_back_to_rec709() -> None:
    rec709 = (0.2126, 0.7152, 0.0722)
    absent = luminance_weights(None)
    assert np.allclose(absent.weights, rec709, atol=1e-4) and "no chromaticities" in absent.source
    # The last: a white point so near y = 0 that the solve loses every digit (a row of
    # +-1e29 that does not sum to 1): refused, not used as weights.
    for broken in ((0, 0, 0, 0, 0, 0, 0.3, 0.3), (0.64, 0.33, 0.3, 0.6, 0.15, 0.06, 0.3, 0.0),
                   (np.nan,) * 8, (0.1, 0.2), (0.64, 0.33, 0.3, 0.6, 0.15, 0.06, 0.3127, 1e-30)):
        fallback = luminance_weights(broken)
        assert np.allclose(fallback.weights, rec709, atol=1e-4)
        assert "unusable" in fallback.source


def test_xyz_encoded_file_weights_green_only() -> None:
    xyz = luminance_weights((1.0, 0.0, 0.0, 1.0, 0.0, 0.0, 1 / 3, 1 / 3))
    assert np.allclose(xyz.weights, (0.0, 1.0, 0.0), atol=1e-9)


def test_non_negative_variant_for_kernels_that_need_it() -> None:
    r, g, b = luminance_weights(AP0).non_negative()
    assert b == 0.0 and np.isclose(r + g, 1.0) and r > 0 and g > 0


def test_filter_weights_are_the_file_weights_unless_one_is_negative() -> None:
    acescg = luminance_weights(ACESCG)
    assert acescg.for_filter() == acescg.weights
    assert "the filter uses" not in acescg.describe()
    # ProPhoto's float64 row sums to 1 + 2e-16, not 1: still used as computed, bit for bit.
    prophoto = luminance_weights(PROPHOTO)
    assert prophoto.for_filter() == prophoto.weights
    ap0 = luminance_weights(AP0)
    assert ap0.for_filter() == ap0.non_negative()
    assert "the filter uses R 0.3208, G 0.6792, B 0.0000" in ap0.describe()


@pytest.mark.parametrize(
    ("chromaticities", "name"),
    [(REC709_CHROMATICITIES, "Rec.709/sRGB"), (ACESCG, "ACEScg (AP1)"),
     (AP0, "ACES2065-1 (AP0)"), (REC2020, "Rec.2020"), (P3_D65, "DCI-P3 D65"),
     (XYZ, "CIE XYZ")],
)
def test_source_names_standard_primaries(chromaticities, name) -> None:
    # The name is what `svgf inspect` and the log show: it must be the file's real space.
    assert luminance_weights(chromaticities).source == f"from chromaticities {name}"


def test_source_lists_unknown_primaries_as_numbers() -> None:
    custom = (0.66, 0.32, 0.29, 0.61, 0.155, 0.065, 0.3127, 0.329)
    source = luminance_weights(custom).source
    assert source == "from chromaticities (0.66, 0.32, 0.29, 0.61, 0.155, 0.065, 0.3127, 0.329)"
