"""Image-quality metrics: plain functions over ``(3, H, W)`` float arrays.

Every function states its formula in its docstring; ``docs/evaluate.md`` repeats them.
``x`` is the image under test, ``r`` the reference. HDR metrics (RMSE, relMSE) work on the
linear radiance as stored in the EXR; the perceptual metrics (PSNR, SSIM, FLIP, temporal
error) work on the display image ``T(x)`` produced by :func:`tone_map`, so a single firefly
of radiance 1000 does not dominate them. The trimmed relMSE drops the largest 0.1 % of
per-pixel errors; the hot-pixel ratio compares output luminance with the reference's local
maximum.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from svgf_cli.errors import UsageError

# relMSE denominator floor: keeps black reference pixels from dividing by zero while
# leaving pixels brighter than ~0.1 essentially relative.
RELMSE_EPSILON = 1e-2

# Trimmed relMSE drops this share of the largest per-pixel errors: above the rate of isolated
# 1-spp fireflies (a few 1e-4 of the pixels), ten times below the area of a real artefact such
# as a lag trail or a smeared reflection (1 % and more), which therefore still counts.
RELMSE_TRIM_FRACTION = 1e-3

# Hot pixels: luminance over the reference's local maximum in a square window of this size,
# plus a floor of this fraction of the reference frame's mean luminance (scale-free, so the
# verdict does not change with exposure; keeps black reference areas from dividing by 0).
HOT_WINDOW = 5
HOT_FLOOR_FRACTION = 1e-2
HOT_THRESHOLD = 3.0

# Rec.709 / sRGB luminance weights (the hot-pixel ratio divides luminances, so the primaries
# of the file barely matter; the references carry no chromaticities anyway).
LUMINANCE_WEIGHTS = (0.2126, 0.7152, 0.0722)

# SSIM constants (Wang et al. 2004): Gaussian window, and C1, C2 for a dynamic range L = 1.
SSIM_WINDOW = 11
SSIM_SIGMA = 1.5
SSIM_K1 = 0.01
SSIM_K2 = 0.03

# FLIP is evaluated in its LDR mode on the tone-mapped (sRGB-encoded) images.
FLIP_MODE = "LDR"

TONE_MAP_DESCRIPTION = (
    "per channel: clamp negatives to 0, Reinhard c/(1+c), then the sRGB transfer function"
)


def tone_map(linear: np.ndarray) -> np.ndarray:
    """Display image in [0, 1]: ``T(c) = srgb(max(c, 0) / (1 + max(c, 0)))`` per channel.

    ``srgb(v) = 12.92 v`` for ``v <= 0.0031308``, else ``1.055 v^(1/2.4) - 0.055``.
    Reinhard maps [0, inf) onto [0, 1) without clipping highlights, so bright light sources
    stay comparable. Returns float32 of the input's shape.
    """
    c = np.maximum(np.asarray(linear, dtype=np.float32), 0.0)
    v = c / (1.0 + c)
    low = v * 12.92
    high = 1.055 * np.power(v, 1.0 / 2.4, dtype=np.float32) - 0.055
    return np.where(v <= 0.0031308, low, high).astype(np.float32)


def nonfinite_pixels(image: np.ndarray) -> int:
    """Number of pixels with at least one NaN or infinite channel (``image`` is (C, H, W))."""
    return int(np.count_nonzero(~np.isfinite(image).all(axis=0)))


def _f64(a: np.ndarray) -> np.ndarray:
    return np.asarray(a, dtype=np.float64)


def rmse(x: np.ndarray, r: np.ndarray) -> float:
    """Root mean squared error on linear radiance: ``sqrt(mean_{p,c} (x - r)^2)``."""
    d = _f64(x) - _f64(r)
    return float(math.sqrt(np.mean(d * d)))


def relmse(x: np.ndarray, r: np.ndarray, epsilon: float = RELMSE_EPSILON) -> float:
    """Relative MSE on linear radiance: ``mean_{p,c} (x - r)^2 / (r^2 + epsilon)``.

    The mean runs over every pixel ``p`` and channel ``c``; ``epsilon`` = 1e-2 by default.
    """
    xd, rd = _f64(x), _f64(r)
    d = xd - rd
    return float(np.mean(d * d / (rd * rd + epsilon)))


def per_pixel_relmse(
    x: np.ndarray, r: np.ndarray, epsilon: float = RELMSE_EPSILON
) -> np.ndarray:
    """Per-pixel relative squared error, float64 (H, W): ``mean_c (x - r)^2 / (r^2 + epsilon)``."""
    xd, rd = _f64(x), _f64(r)
    d = xd - rd
    return np.mean(d * d / (rd * rd + epsilon), axis=0)


def relmse_trimmed(
    x: np.ndarray,
    r: np.ndarray,
    fraction: float = RELMSE_TRIM_FRACTION,
    epsilon: float = RELMSE_EPSILON,
) -> float:
    """relMSE without its largest per-pixel values (fireflies).

    With ``e_p = mean_c (x - r)^2 / (r^2 + epsilon)`` over the ``N`` pixels sorted ascending,
    drop the ``k = floor(fraction * N)`` largest and average the rest:
    ``relMSE_trim = (1 / (N - k)) * sum_{i < N - k} e_(i)``. ``fraction`` = 1e-3 by default;
    below 1000 pixels nothing is dropped and it equals :func:`relmse`.
    """
    errors = per_pixel_relmse(x, r, epsilon).ravel()
    drop = math.floor(fraction * errors.size)
    if drop:
        errors = np.partition(errors, errors.size - drop - 1)[: errors.size - drop]
    return float(np.mean(errors))


def luminance(image: np.ndarray) -> np.ndarray:
    """Rec.709 luminance (H, W) float64 of a (3, H, W) linear RGB image."""
    wr, wg, wb = LUMINANCE_WEIGHTS
    rgb = _f64(image)
    return wr * rgb[0] + wg * rgb[1] + wb * rgb[2]


def local_maximum(plane: np.ndarray, size: int = HOT_WINDOW) -> np.ndarray:
    """Maximum over the ``size`` x ``size`` window centred on each pixel (clipped at the
    image border: only pixels inside the image count)."""
    radius = size // 2
    padded = np.pad(plane, radius, mode="constant", constant_values=-np.inf)
    windows = np.lib.stride_tricks.sliding_window_view(padded, (size, size))
    return windows.max(axis=(2, 3))


def hot_pixel_ratio(x: np.ndarray, r: np.ndarray) -> np.ndarray:
    """Per-pixel ``L(x)_p / (max_{q in 5x5(p)} L(r)_q + f)``, float64 (H, W).

    ``L`` is Rec.709 luminance, the window is clipped at the border, and the floor
    ``f = 0.01 * mean_p L(r)_p`` (a tiny absolute 1e-12 when the reference is black).
    A value above 3 is an output pixel far brighter than anything near it in the reference:
    a firefly the filter made or let through.
    """
    lum_r = luminance(r)
    floor = max(HOT_FLOOR_FRACTION * float(np.mean(lum_r)), 1e-12)
    return luminance(x) / (local_maximum(lum_r) + floor)


def hot_pixels(
    x: np.ndarray, r: np.ndarray, threshold: float = HOT_THRESHOLD
) -> tuple[float, float]:
    """``(max_p ratio_p, share of pixels with ratio_p > threshold)`` of :func:`hot_pixel_ratio`."""
    ratio = hot_pixel_ratio(x, r)
    return float(ratio.max()), float(np.count_nonzero(ratio > threshold)) / ratio.size


def psnr(x_display: np.ndarray, r_display: np.ndarray) -> float:
    """PSNR in dB of display images with peak 1: ``10 log10(1 / mean_{p,c} (T(x) - T(r))^2)``.

    Identical images give ``math.inf``.
    """
    d = _f64(x_display) - _f64(r_display)
    mse = float(np.mean(d * d))
    if mse == 0.0:
        return math.inf
    return 10.0 * math.log10(1.0 / mse)


def gaussian_window(size: int = SSIM_WINDOW, sigma: float = SSIM_SIGMA) -> np.ndarray:
    """Normalised 1-D Gaussian taps ``exp(-k^2 / (2 sigma^2))``, ``k = -(size-1)/2 .. ``."""
    k = np.arange(size, dtype=np.float64) - (size - 1) / 2.0
    taps = np.exp(-(k * k) / (2.0 * sigma * sigma))
    return taps / taps.sum()


def _filter_valid(planes: np.ndarray, taps: np.ndarray) -> np.ndarray:
    """Separable filter of (C, H, W) planes, keeping only fully covered ('valid') pixels."""
    n = len(taps)
    h, w = planes.shape[1:]
    rows = sum(taps[i] * planes[:, i : i + h - n + 1, :] for i in range(n))
    return sum(taps[i] * rows[:, :, i : i + w - n + 1] for i in range(n))


def ssim(x_display: np.ndarray, r_display: np.ndarray) -> float:
    """Mean SSIM over the three channels of display images (Wang et al. 2004).

    Per channel, with Gaussian-weighted local statistics (11x11 window, sigma 1.5, 'valid'
    pixels only, i.e. no padding at the border)::

        SSIM = (2 mu_x mu_r + C1)(2 s_xr + C2) / ((mu_x^2 + mu_r^2 + C1)(s_x^2 + s_r^2 + C2))

    with ``C1 = (0.01 L)^2``, ``C2 = (0.03 L)^2``, ``L = 1``. The result is the mean of the
    SSIM map over pixels and channels. Images smaller than 11 pixels use the largest odd
    window that fits.
    """
    x, r = _f64(x_display), _f64(r_display)
    if x.shape != r.shape:
        raise ValueError(f"shape mismatch {x.shape} vs {r.shape}")
    size = min(SSIM_WINDOW, x.shape[1], x.shape[2])
    size -= 1 - size % 2
    taps = gaussian_window(size, SSIM_SIGMA)
    c1 = (SSIM_K1 * 1.0) ** 2
    c2 = (SSIM_K2 * 1.0) ** 2
    mu_x = _filter_valid(x, taps)
    mu_r = _filter_valid(r, taps)
    var_x = _filter_valid(x * x, taps) - mu_x * mu_x
    var_r = _filter_valid(r * r, taps) - mu_r * mu_r
    cov = _filter_valid(x * r, taps) - mu_x * mu_r
    numerator = (2.0 * mu_x * mu_r + c1) * (2.0 * cov + c2)
    denominator = (mu_x * mu_x + mu_r * mu_r + c1) * (var_x + var_r + c2)
    return float(np.mean(numerator / denominator))


def flip(x_display: np.ndarray, r_display: np.ndarray) -> tuple[float, np.ndarray]:
    """Mean LDR-FLIP error (NVIDIA, Andersson et al. 2020) and its (H, W) error map.

    Computed by the ``flip-evaluator`` package in LDR mode on the sRGB-encoded display images
    (default 67 pixels per degree). 0 = indistinguishable, 1 = maximal difference.
    """
    try:
        import flip_evaluator  # deferred: loading it costs time `svgf --help` should not pay
    except ImportError as exc:
        raise UsageError(
            "FLIP needs the flip-evaluator package: pip install flip-evaluator"
        ) from exc

    ref = np.ascontiguousarray(np.clip(np.moveaxis(r_display, 0, -1), 0.0, 1.0), np.float32)
    test = np.ascontiguousarray(np.clip(np.moveaxis(x_display, 0, -1), 0.0, 1.0), np.float32)
    error_map, mean, _ = flip_evaluator.evaluate(
        ref, test, FLIP_MODE, inputsRGB=True, applyMagma=False, computeMeanError=True
    )
    return float(mean), np.asarray(error_map, dtype=np.float32).reshape(ref.shape[:2])


def temporal_error(
    x_display: np.ndarray,
    x_previous: np.ndarray,
    r_display: np.ndarray,
    r_previous: np.ndarray,
) -> float:
    """Flicker: ``mean_{p,c} |(T(x_t) - T(x_{t-1})) - (T(r_t) - T(r_{t-1}))|``.

    The output's frame-to-frame change minus the reference's: genuine motion and lighting
    changes cancel, noise and flicker that the reference does not have remain. 0 = the output
    changes exactly as the reference does.
    """
    change = _f64(x_display) - _f64(x_previous)
    expected = _f64(r_display) - _f64(r_previous)
    return float(np.mean(np.abs(change - expected)))


# Hot pixels (issue 14): an output pixel is hot when its brightest channel exceeds this many
# times the brightest reference value in its PEAK_WINDOW x PEAK_WINDOW neighbourhood.
PEAK_WINDOW = 5
PEAK_FACTOR = 3.0
# Reference maxima below this count as this (a dim pixel over a black reference is noise,
# not a firefly).
PEAK_FLOOR = 1e-2


def peak_ratio(x: np.ndarray, r: np.ndarray) -> tuple[float, float]:
    """Hot pixels: ``q(p) = max_c x_c(p) / max(max_{q in 5x5(p), c} r_c(q), PEAK_FLOOR)``.

    Returns ``(max_p q(p), share of pixels with q(p) > PEAK_FACTOR)`` on linear radiance; the
    window is clipped at the image border. Issue 14's target is no pixel above 3.
    """
    image = _f64(x).max(axis=0)
    reference = _f64(r).max(axis=0)
    radius = PEAK_WINDOW // 2
    padded = np.pad(reference, radius, mode="edge")
    windows = np.lib.stride_tricks.sliding_window_view(padded, (PEAK_WINDOW, PEAK_WINDOW))
    bound = np.maximum(windows.max(axis=(-2, -1)), PEAK_FLOOR)
    ratio = image / bound
    return float(ratio.max()), float(np.mean(ratio > PEAK_FACTOR))


@dataclass(frozen=True)
class MetricInfo:
    """How a metric is named, read, summarised over frames and ranked.

    ``summary`` is how per-frame values become one number per method: ``"mean"`` (the
    arithmetic mean) or ``"max"`` (the worst frame). ``overall``: whether the metric's rank
    enters the overall rank (the trimmed relMSE would count relMSE twice, the hot-pixel
    metrics are a pass/fail diagnostic, so they are ranked on their own only).
    """

    key: str
    label: str
    higher_is_better: bool
    formula: str
    unit: str = ""
    summary: str = "mean"
    overall: bool = True


METRICS: tuple[MetricInfo, ...] = (
    MetricInfo("rmse", "RMSE", False, "sqrt(mean (x-r)^2) on linear radiance"),
    MetricInfo(
        "relmse",
        "relMSE",
        False,
        f"mean (x-r)^2/(r^2+{RELMSE_EPSILON:g}) on linear radiance",
    ),
    MetricInfo(
        "relmse_trimmed",
        "relMSE (trimmed)",
        False,
        f"per pixel e = mean_c (x-r)^2/(r^2+{RELMSE_EPSILON:g}); mean of e without its largest "
        f"{RELMSE_TRIM_FRACTION:.1%} (floor of the share times the pixel count)",
        overall=False,
    ),
    MetricInfo("psnr", "PSNR", True, "10 log10(1/mean (T(x)-T(r))^2) on display images", "dB"),
    MetricInfo("ssim", "SSIM", True, "mean over R,G,B of SSIM (11x11 Gaussian, sigma 1.5)"),
    MetricInfo("flip", "FLIP", False, "mean LDR-FLIP on display images (flip-evaluator)"),
    MetricInfo(
        "temporal",
        "Temporal",
        False,
        "mean |(T(x_t)-T(x_t-1)) - (T(r_t)-T(r_t-1))|, from the second frame on",
    ),
    MetricInfo(
        "hot_max",
        "Hot max",
        False,
        f"max over pixels of L(x) / (max of L(r) in the {HOT_WINDOW}x{HOT_WINDOW} window + "
        f"{HOT_FLOOR_FRACTION:g} mean L(r)), Rec.709 luminance; worst frame",
        summary="max",
        overall=False,
    ),
    MetricInfo(
        "hot_share",
        "Hot share",
        False,
        f"share of pixels whose hot-pixel ratio exceeds {HOT_THRESHOLD:g}",
        overall=False,
    ),
)
METRIC_KEYS: tuple[str, ...] = tuple(m.key for m in METRICS)
METRIC_INFO: dict[str, MetricInfo] = {m.key: m for m in METRICS}
