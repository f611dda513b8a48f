"""SVGF parameters: one flat dataclass with the paper's defaults, each documented once.

Every field's metadata is the single place its meaning (``help``), its group (``group``, one
of ``GROUPS``) and its valid range (``valid``, a ``Range``) are written down: ``check_params``
checks the range, the CLI builds its click types, ``--set NAME=VALUE`` and ``svgf params``
from them (``svgf_cli.commands.options``), and the resolved values are stored in every
output's metadata as ``svgf/params``. The grouping is metadata only: the dataclass stays flat,
so ``to_json`` and history files do not change.

A preset is the paper's values plus a named list of departures, each with its reason
(``DEPARTURES``).
"""

from __future__ import annotations

import dataclasses
import json
import math
from dataclasses import dataclass, field
from typing import Any, NamedTuple, TypeVar

# ``atrous_iterations`` value that picks the count from the image size.
AUTO_ITERATIONS = -1
# ``pixel_filter`` from the frame's header (svgf_cli.filters.pixel_filter).
AUTO_PIXEL_FILTER = -1.0
# ``medium_coverage_radius`` from the image's size (medium_coverage_radius_for).
AUTO_COVERAGE = -1
# From this many rows (the shorter side) the auto coverage is at least 5x5: at 640x360 the
# 3x3 one mottled production's fog (relMSE there 0.0268 against 0.0171; video JOD 8.670
# against 8.675), at 384x216 5x5 lost video JOD (8.507 against 8.498).
MEDIUM_COVERAGE_ROWS = 320
# ``samples_per_pixel`` from the frame's header (params_for_samples).
AUTO_SAMPLES = -1
# ``history_clamp_radius`` from the image's size (history_clamp_radius_for).
AUTO_CLAMP_RADIUS = -1
# ``luminance_stop_scale`` from the image's size (luminance_stop_scale_for).
AUTO_STOP_SCALE = -1.0
# ``antilag_radius`` from the image's size (antilag_radius_for).
AUTO_ANTILAG_RADIUS = -1

# The parameter groups, in display order, with a one-line title each.
GROUPS: dict[str, str] = {
    "temporal": "temporal accumulation and reprojection (paper 4.1)",
    "variance": "variance estimation (paper 4.2)",
    "antilag": "anti-lag: history that no longer matches the frame is shortened",
    "glossy": "glossy signals (reflections move with what they show)",
    "atrous": "the a-trous wavelet filter (paper 4.3)",
    "demodulation": "demodulation and remodulation by the albedo (paper 4)",
    "guards": "guards: firefly clamp and spread, history clamp, despike",
    "output": "the output: pixel filter and temporal anti-aliasing",
}


@dataclass(frozen=True)
class Range:
    """The valid values of a numeric parameter: ``low``/``high`` (None = unbounded; open or
    closed), plus ``auto`` (a sentinel the user writes as ``auto``) and ``off`` (a value
    outside the range that switches the feature off)."""

    low: float | None = None
    high: float | None = None
    low_open: bool = False
    high_open: bool = False
    auto: float | None = None
    off: float | None = None
    shown: str | None = None  # how the bounds are written, where the default text is poor
    noun: str = "a number"  # what a value is, for "expected ..." messages

    def in_bounds(self, value: float) -> bool:
        if self.low is not None and (value < self.low or (self.low_open and value == self.low)):
            return False
        return self.high is None or not (value > self.high
                                          or (self.high_open and value == self.high))

    def contains(self, value: float) -> bool:
        return value in (self.auto, self.off) or self.in_bounds(value)

    def bounds_text(self) -> str:
        """``(0, 1]``, ``[1, 16]``, ``> 0``, ``>= 1``."""
        if self.shown is not None:
            return self.shown
        low, high = (None if b is None else f"{b:g}" for b in (self.low, self.high))
        if low is not None and high is not None:
            return f"{'(' if self.low_open else '['}{low}, {high}{')' if self.high_open else ']'}"
        if low is not None:
            return f"{'>' if self.low_open else '>='} {low}"
        return f"{'<' if self.high_open else '<='} {high}" if high is not None else "any"

    def text(self) -> str:
        """The whole range as a user reads it: ``0..12 or auto``, ``0 (off) or >= 1``."""
        text = self.bounds_text()
        if self.off is not None:
            text = f"{self.off:g} (off) or {text}"
        return f"{text} or auto" if self.auto is not None else text


def _p(default: Any, help: str, *, group: str, valid: Range | None = None) -> Any:
    assert group in GROUPS, group
    return field(default=default, metadata={"help": help, "group": group, "valid": valid})


@dataclass(frozen=True)
class SVGFParams:
    """Resolved SVGF parameters. Defaults are Schied et al. 2017 (``--preset paper``)."""

    # Temporal accumulation (paper section 4.1).
    alpha: float = _p(0.2, "Minimum colour blend factor; alpha = max(alpha, 1/history_length).",
                      group="temporal", valid=Range(0, 1, low_open=True))
    moments_alpha: float = _p(0.2, "Minimum blend factor of the luminance moments.",
                              group="temporal", valid=Range(0, 1, low_open=True))
    samples_per_pixel: int = _p(
        1, "Samples per pixel of the inputs: N-sample frames blend as N one-sample frames"
        " (alpha, moments_alpha -> 1 - (1 - alpha)^N; colour means: K^2/(1-K) = N a^2/(1-a)),"
        " the auto reaches halved per factor 4; auto (-1 in svgf/params) = the frame's header"
        " (Cycles'; else 1): docs/algorithm.md#frames-of-several-samples.",
        group="temporal", valid=Range(1, 65536, auto=AUTO_SAMPLES, shown="1..65536"),
    )
    history_cap: int = _p(32, "Maximum history length in frames.", group="temporal", valid=Range(1))
    temporal: bool = _p(True, "Reuse history through motion vectors (off: every frame cold).",
                        group="temporal")
    depth_tolerance: float = _p(
        10.0, "Reprojection rejects a tap when |z_prev - z| > tolerance * (depth_gradient"
        " + depth_slack * z).", group="temporal", valid=Range(0))
    depth_slack: float = _p(
        0.002, "Depth-relative slack of the reprojection depth test (scale-free stand-in for"
        " Falcor's absolute 0.01).", group="temporal", valid=Range(0))
    normal_tolerance: float = _p(
        16.0, "Reprojection rejects a tap when |n - n_prev| > tolerance * (normal_gradient"
        " + 0.01).", group="temporal", valid=Range(0))
    history_catmull_rom: bool = _p(
        False, "Resample the colour history and moments with a Catmull-Rom spline (clamped to"
        " the bilinear taps' range) where all 16 taps pass the tests, else bilinear.",
        group="temporal")
    bidirectional: bool = _p(
        False, "Offline: also run the filter backwards in time and combine both passes' histories"
        " per pixel before the spatial filter (frames after the current one count too;"
        " about twice the work; docs/bidirectional.md).", group="temporal")
    warm_start: int = _p(
        0, "The first N output frames of a cold start (a shot's first frames) from a"
        " bidirectional run over its first 2N frames, not noisy (default preset: 8; 0: off;"
        " later frames unchanged; docs/stability.md#warm-start).",
        group="temporal", valid=Range(0, 16),
    )
    medium_fill_radius: int = _p(
        0, "Pixels whose sample scattered in fog or smoke (no surface, volume light around)"
        " take the G-buffer of the nearest surface within this many pixels, or become a"
        " medium surface, and are filtered, not passed through (0: off;"
        " docs/algorithm.md#volumes-medium-pixels).",
        group="temporal", valid=Range(0, 16),
    )
    medium_coverage_radius: int = _p(
        0,
        "The medium's signal is demodulated by its coverage: the share of the (2 r + 1)^2"
        " pixels around each pixel whose sample scattered in the medium (0: off, filtered as"
        " radiance; needs medium_fill_radius); auto (-1 in svgf/params) = 1 below 320 rows,"
        " else one per 360, at least 2 (docs/algorithm.md#the-mediums-coverage).",
        group="temporal", valid=Range(0, 8, auto=AUTO_COVERAGE, shown="0..8", noun="a radius"),
    )
    medium_motion: bool = _p(
        False, "Medium pixels reproject with the surface behind's motion or none, whichever"
        " their light follows (docs/algorithm.md#the-mediums-motion).", group="temporal")
    # Variance estimation (paper section 4.2).
    variance_history_threshold: int = _p(
        4, "Below this history length the variance is estimated spatially (7x7 bilateral).",
        group="variance", valid=Range(0))
    spatial_variance_radius: int = _p(3, "Radius of the spatial variance estimate (3 = 7x7).",
                                      group="variance", valid=Range(0))
    spatial_variance_sigma_luminance: float = _p(
        10.0,
        "Weak luminance edge-stop of the spatial variance estimate, relative to the pair's"
        " mean luminance: exp(-|dl| / (sigma * mean l)) (Falcor's raw phiColor at l = 1,"
        " the same at every brightness).",
        group="variance", valid=Range(0, low_open=True),
    )
    spatial_variance_blur_color: bool = _p(
        False,
        "Also replace short-history colour by the spatially filtered colour (Falcor; the"
        " paper filters only the variance).",
        group="variance",
    )
    # Anti-lag (filters/antilag.py): history that no longer matches the frame is shortened.
    antilag: bool = _p(
        False,
        "Shorten the history where it disagrees with the current frame beyond the noise"
        " (moving lights and shadows, lights switched or dimmed, moving reflections).",
        group="antilag",
    )
    antilag_radius: int = _p(
        2, "Anti-lag window radius in cells of 2x2 pixels (2 = 5x5 cells, 10x10 pixels); auto"
        " (-1 in svgf/params) = from the image's shorter side: 2 below 160 pixels, 4 below"
        " 320, else 6; halved per factor 4 of samples_per_pixel.",
        group="antilag", valid=Range(1, 16, auto=AUTO_ANTILAG_RADIUS, shown="1..16"))
    antilag_sigma: float = _p(
        3.5, "Anti-lag significance: the history is stale, with its full weight, where it"
        " differs from the frame by more than this many standard errors of the window's noise.",
        group="antilag", valid=Range(0))
    antilag_sigma_start: float = _p(
        2.0, "Anti-lag: from this many standard errors the weight ramps in, linearly, to full at"
        " antilag_sigma (at or above it: a step there).", group="antilag", valid=Range(0))
    antilag_spatial_samples: float = _p(
        64.0, "Anti-lag strength: pixels the spatial filter is assumed to average; the current"
        " frame gets weight b^2 / (b^2 + var / N) for a stale history of bias b.",
        group="antilag", valid=Range(1))
    antilag_tolerance: float = _p(
        0.02, "Anti-lag relative tolerance: history within this fraction of the frame is kept.",
        group="antilag", valid=Range(0))
    antilag_gain: bool = _p(
        False, "Anti-lag first rescales the history where a wide neighbourhood's light changed"
        " by one factor (a light switched or dimmed) and narrower windows agree; causal runs.",
        group="antilag")
    antilag_gradients: bool = _p(
        True, "Anti-lag also uses temporal gradient samples (A-SVGF) when the input has them"
        " (svgf trace --gradient-samples).", group="antilag")
    object_history: bool = _p(
        False,
        "On an object turning about its own axis (a rolling ball), also fetch the light's"
        " history at the object's translation, and keep it where anti-lag trusts it more"
        " than the material point's (needs antilag and an object id pass).",
        group="antilag",
    )
    # Glossy signals (Signal.glossy: reflections and refractions move with what they show,
    # not with the surface, so their reprojected history is unreliable).
    glossy_history_clamp: float = _p(
        0.0, "Clamp a glossy signal's reprojected history to the current 3x3 mean +- k*sigma"
        " (0 = as history_clamp).", group="glossy", valid=Range(0))
    glossy_sigma_luminance: float = _p(
        0.0, "sigma_l of glossy signals: reflections carry detail the spatial filter must keep"
        " (0 = the same as sigma_luminance).", group="glossy", valid=Range(0))
    mixed_sigma_luminance: float = _p(
        0.0, "sigma_l of signals holding direct and indirect light together (a combined colour,"
        " one lobe's whole light): their variance is the indirect light's (0 = the same as"
        " sigma_luminance; glossy signals keep glossy_sigma_luminance).",
        group="glossy", valid=Range(0))
    glossy_emitter_radiance: bool = _p(
        False,
        "Filter a glossy signal as radiance where the G-buffer albedo is no reflectance"
        " (brightest channel above 1.05: Cycles' Denoising Albedo holds the light's emission"
        " where a specular path reached a light) at the pixel and two neighbours (one on a"
        " sharp mirror), off a light's large image: a small reflected light is filtered with"
        " the pixels that also see it, not blurred into the surface around it.",
        group="glossy",
    )
    reflected_albedo: bool = _p(
        False, "Demodulate a glossy signal by the G-buffer albedo on diffuse-free objects whose"
        " albedo shows a sharp reflection (Cycles' Denoising Albedo follows specular bounces).",
        group="glossy")
    glossy_spread_fireflies: bool = _p(
        False, "With spread_fireflies, also spread a glossy signal's fireflies, over their 3x3"
        " and at most their bound to each pixel (rare hits of a highlight or its glow).",
        group="glossy")
    glossy_heavy_tail: float = _p(
        0.0, "A glossy pixel whose history's luminance moments have a relative variance above"
        " this (light from rare bright samples) takes the history clamp's wider window unless"
        " its object's reflections are rough (0 = off).", group="glossy", valid=Range(0))
    # A-trous wavelet filter (paper section 4.3).
    atrous_iterations: int = _p(
        5,
        "Number of a-trous iterations (steps 1, 2, 4, ...); 0 = none; auto (-1 in"
        " svgf/params) = from the image's shorter side: 3 below 160 pixels, 4 below 320,"
        " else 5; one fewer per whole factor of 4 of the frame's samples per pixel.",
        group="atrous", valid=Range(
            0, 12, auto=AUTO_ITERATIONS, shown="0..12", noun="a number of iterations"
        ),
    )
    feedback_iteration: int = _p(
        0, "A-trous iteration whose output becomes the colour history (-1 = unfiltered).",
        group="atrous", valid=Range(-1),
    )
    moving_feedback_share: float = _p(
        1.0,
        "Share of the feedback iteration's output in the colour history where the pixel"
        " moves (the rest: the unfiltered accumulation; 1 = the paper's feedback everywhere).",
        group="atrous", valid=Range(0, 1),
    )
    sigma_luminance: float = _p(4.0, "sigma_l: luminance edge-stopping against sqrt(variance).",
                                group="atrous", valid=Range(0, low_open=True))
    sigma_normal: float = _p(128.0, "sigma_n: exponent of the normal edge-stopping weight.",
                             group="atrous", valid=Range(0, low_open=True))
    sigma_depth: float = _p(1.0, "sigma_z: depth edge-stopping against the depth gradient.",
                            group="atrous", valid=Range(0, low_open=True))
    luminance_stop_scale: float = _p(
        1.0, "Factor on every a-trous sigma_l (sigma_luminance, mixed_ and glossy_); auto (-1 in"
        " svgf/params) = from the image's shorter side: 0.5 below 120 pixels, 1 below 320, 1.75"
        " below 640, else 3.", group="atrous", valid=Range(0, low_open=True, auto=AUTO_STOP_SCALE))
    luminance_guide_blur: bool = _p(False, "The a-trous luminance stops compare 3x3 Gaussian"
        " means of luminance, not one-sample values whose noise weighs the taps.", group="atrous")
    mixed_symmetric_stop: bool = _p(False, "The a-trous luminance stop of a mixed signal (a"
        " combined colour) divides by the geometric mean of both pixels' deviations, not the"
        " centre's alone: symmetric weights.", group="atrous")
    # Demodulation (paper section 4).
    albedo_epsilon: float = _p(
        1e-3,
        "Demodulation floor: a signal's colour below it in every channel is black and filtered"
        " as radiance; otherwise each channel is floored at max(albedo_epsilon, 0.02 * the"
        " brightest channel).",
        group="demodulation", valid=Range(0, low_open=True),
    )
    guide_albedo_floor: float = _p(
        0.0,
        "Demodulation floor of signals demodulated by the G-buffer albedo (a combined colour"
        " over the renderer's albedo AOV): glossy light over a dark diffuse base is not"
        " modulated by that albedo, and dividing by it amplifies the light (0 ="
        " albedo_epsilon).",
        group="demodulation", valid=Range(0, 1),
    )
    temporal_albedo: bool = _p(
        False,
        "Remodulate each signal (not glossy ones) by its demodulation colour's running mean"
        " over frames"
        " (reprojected, clamped to the current 3x3 range; without history a 3x3 Gaussian"
        " mean): at 1 spp a pixel's colour is one sample of a texture edge, a renderer's"
        " reference the pixel-filtered mean (off for a renderer whose references are point"
        " samples, as svgf trace's are by default: the mean only blurs them).",
        group="demodulation",
    )
    albedo_catmull_rom: bool = _p(
        False,
        "Resample the temporal albedo's colour means with a Catmull-Rom spline over the 4x4"
        " taps (clamped to the bilinear taps' range) where all 16 pass its tests, bilinear"
        " elsewhere: bilinear resampling blurs the texture the means converge to a little"
        " more every frame.",
        group="demodulation",
    )
    # Optional extras from the lecture notes; all off unless asked.
    firefly_clamp: float = _p(
        0.0,
        "Clamp input luminance to mean + k*sigma of the 8 neighbours before accumulation"
        " (0 = off).",
        group="guards", valid=Range(0),
    )
    spread_fireflies: float = _p(
        0.0,
        "Before accumulation, a sample above both its history's m1 + k*sigma and 4x its"
        " second-brightest same-mode neighbour is bounded there and its excess shared over the"
        " same surface in the 9x9 around it (energy kept; glossy signals: glossy_spread_"
        "fireflies; 0 = off).",
        group="guards", valid=Range(0),
    )
    history_clamp: float = _p(
        0.0,
        "Clamp the reprojected history to the 3x3 mean +- k*sigma of the current frame,"
        " its luminance moments scaled with it (0 = off; glossy signals: glossy_history_clamp).",
        group="guards", valid=Range(0),
    )
    history_clamp_radius: int = _p(
        1, "The history clamp's window: the (2 r + 1)^2 pixels (1: the 3x3, which glossy"
        " signals with their own k keep); auto (-1 in svgf/params) = from the image's shorter"
        " side: 1 below 160 pixels, 2 below 320, else 3.",
        group="guards", valid=Range(1, 8, auto=AUTO_CLAMP_RADIUS, shown="1..8", noun="a radius"),
    )
    despike: float = _p(
        0.0,
        "Output guard: a filtered pixel brighter than this many times its second-brightest"
        " same-mode neighbour (any neighbour, in the output, for a pixel whose mode none"
        " shares) is brought down to that bound (fireflies the a-trous kept; 0 = off).",
        group="guards", valid=Range(1, off=0),
    )
    pixel_filter: float = _p(
        0.0,
        "Neighbour weight w of a [w, 1-2w, w] kernel per axis applied to the output without"
        " its emission: the renderer's pixel filter, which frames sampled at pixel centres"
        " lack (0 = off; auto (-1 in svgf/params) = 0.05 where the header says the frame is"
        " one sample through the pixel centre, Cycles at 1 spp, else off).",
        group="output",
        valid=Range(0, 1 / 3, auto=AUTO_PIXEL_FILTER, shown="0..1/3", noun="a weight"),
    )
    edge_filter: float = _p(
        0.0,
        "Weight w each pair of neighbouring pixels on two surfaces (another object, the"
        " background, a depth step) exchanges of its whole colour, emission included: the"
        " renderer's pixel filter across outlines, which frames sampled at pixel centres lack"
        " (0 = off; auto (-1 in svgf/params) = 0.05 where the header says the frame is one"
        " sample through the pixel centre, else off).",
        group="output",
        valid=Range(0, 0.25, auto=AUTO_PIXEL_FILTER, shown="0..1/4", noun="a weight"),
    )
    noisy_outline_weight: float = _p(
        0.0, "Where over 30 % of the pixel pairs around a pixel change object (a defocused"
        " region: the G-buffer is noise), each such pair exchanges up to this much more of"
        " its colour, four times; all of it at a lone sample among such pairs on a"
        " centre-sampled frame (0 = off;"
        " docs/algorithm.md#noisy-outlines-defocus).",
        group="output", valid=Range(0, 0.25, shown="0..1/4", noun="a weight"),
    )
    taa: bool = _p(False, "Temporal anti-aliasing of the output at object outlines (the paper's"
                   " last step): the previous output, resampled and clipped to the current 3x3,"
                   " blended in where a jittered sample flips surfaces.", group="output")
    taa_jittered: bool = _p(False, "taa on the frames whose G-buffer shows jittered samples (a"
                            " plane's depth off the line of pixel centres) unless the header"
                            " says centre-sampled.", group="output")
    taa_alpha: float = _p(0.5, "The current output's share in the TAA blend.", group="output",
                          valid=Range(0, 1, low_open=True))
    still_emission_mean: bool = _p(False, "On jittered frames, the emission added back is its"
                                   " mean over frames where nothing moves: a still light's"
                                   " outline shows its coverage.", group="output")

    def to_json(self) -> str:
        """Stable JSON of every field (sorted keys), stored in output metadata."""
        return json.dumps(dataclasses.asdict(self), sort_keys=True)

    def replace(self, **changes: Any) -> SVGFParams:
        return dataclasses.replace(self, **changes)


class Departure(NamedTuple):
    """One value a preset changes from the paper's, and why."""

    name: str
    value: Any
    reason: str


_ALG = "docs/algorithm.md"
_FIREFLIES = f"{_ALG}#fireflies-despike-and-the-short-history-variance"
_GLOSSY = f"{_ALG}#2a-anti-lag-and-glossy-signals"
_FALCOR = "Falcor's SVGFPass default (shared/research/svgf-anchors.md, section 2)"

# Each preset is the paper's values (Schied et al. 2017: alpha 0.2, sigma_l 4, sigma_n 128,
# sigma_z 1, 5 iterations, the first fed back as history) plus these departures.
DEPARTURES: dict[str, tuple[Departure, ...]] = {
    "paper": (),
    # The recommended set: it wins overall on every bundled sequence (docs/results.md).
    "default": (
        Departure("feedback_iteration", -1, "a history filtered by the a-trous feeds its"
                  " blotches back frame after frame (still pixels too): docs/stability.md"
                  "#the-default-since-2026-11-27"),
        Departure("antilag", True, "moving lights and shadows, lights switched or dimmed"
                  f" and moving reflections lag otherwise: {_GLOSSY}"),
        Departure("antilag_radius", AUTO_ANTILAG_RADIUS, "on frames larger than the fixtures'"
                  " 128x72 the 10x10 window's noise cuts histories short where nothing"
                  " changed (antilag_radius_for): "
                  f"{_ALG}#the-anti-lag-window-grows-with-the-image"),
        Departure("antilag_gain", True, "a light switched or dimmed changes the level of"
                  " the light, not its shape: the history rescaled keeps its length:"
                  f" {_ALG}#the-history-gain"),
        Departure("object_history", True, "a turning object's points turn away from the"
                  " light: their light's history is at the object's translation, not the"
                  f" material point's: {_ALG}#turning-objects"),
        Departure("history_clamp", 3.0, "a loose clamp of the history against outliers:"
                  f" {_GLOSSY}"),
        Departure("history_clamp_radius", AUTO_CLAMP_RADIUS, "at one sample a dark surface"
                  " lit by rare indirect samples shows a 3x3 of zeros most frames, which clamps"
                  " its history to black: blotches, and the frame darker, on frames larger"
                  f" than the fixtures' 128x72 (history_clamp_radius_for): {_ALG}"
                  "#the-history-clamps-window"),
        Departure("luminance_stop_scale", AUTO_STOP_SCALE, "on frames larger than the"
                  " fixtures' 128x72 the stops tuned there keep 1-spp noise apart as detail:"
                  " blotches, and a video that boils (luminance_stop_scale_for): "
                  f"{_ALG}#the-luminance-stop-grows-with-the-image"),
        Departure("luminance_guide_blur", True, "a one-sample luminance in the stop gives a"
                  " bright sample less weight than a dark one: the filtered frame was 2-7 %"
                  f" darker than the truth: {_ALG}#the-luminance-stops-guide"),
        Departure("mixed_symmetric_stop", True, "with the centre's deviation alone a bright"
                  " sample's own stop is loose and its dim neighbours' tight: its light was"
                  f" lost: {_ALG}#a-symmetric-stop-for-mixed-signals"),
        Departure("glossy_history_clamp", 1.0, "reflections move with what they show, so"
                  f" their reprojected history is unreliable: {_GLOSSY}"),
        Departure("sigma_luminance", 2.0, "with the unfiltered history and the warm start,"
                  " the paper's 4 standard deviations blur lighting into low-frequency"
                  " blotches that drift from frame to frame: docs/stability.md"
                  "#a-tighter-luminance-stop"),
        Departure("glossy_sigma_luminance", 1.0, "reflections carry detail the spatial filter"
                  " must keep: docs/signals.md"),
        Departure("glossy_emitter_radiance", True, "a reflected light is filtered as radiance,"
                  " not blurred into the surface around it: docs/signals.md"),
        Departure("reflected_albedo", True, "a mirror's reflected texture is detail the"
                  " glossy stop keeps, and its noise with it: docs/algorithm.md"
                  "#reflected-albedo"),
        Departure("mixed_sigma_luminance", 1.5, "a combined colour's variance is the indirect"
                  f" light's, which would blur the direct light's detail: {_ALG}"
                  "#4-à-trous-wavelet-filter-paper-43 (2.5 before docs/stability.md"
                  "#a-tighter-luminance-stop)"),
        Departure("spatial_variance_sigma_luminance", 0.5, "fireflies and lit/shadowed"
                  " neighbours no longer inflate the short-history variance into an"
                  f" over-blur: {_FIREFLIES}"),
        Departure("despike", 2.0, f"bounds the fireflies the a-trous kept: {_FIREFLIES}"),
        Departure("spread_fireflies", 10.0, "shares a firefly's excess over its surface,"
                  f" energy kept: {_FIREFLIES}"),
        Departure("glossy_spread_fireflies", True, "a glossy signal's lone bright sample is a"
                  " rare hit of a highlight or its glow, which the glossy history clamp would"
                  f" drop: {_ALG}#glossy-fireflies"),
        Departure("glossy_heavy_tail", 2.0, "a heavy-tailed reflection's or refraction's rare"
                  " bright samples are seldom in this frame's 3x3, so that bound pulls its"
                  f" history dark: {_ALG}#heavy-tailed-glossy-light"),
        Departure("guide_albedo_floor", 0.1, "glossy light over a dark diffuse base is not"
                  " amplified by dividing by the G-buffer albedo: "
                  f"{_ALG}#1-signals-and-demodulation"),
        Departure("temporal_albedo", True, "a renderer's reference is the pixel-filtered"
                  " texture, a 1-spp colour one sample of it: "
                  f"{_ALG}#5-remodulation-and-the-temporal-albedo"),
        Departure("samples_per_pixel", AUTO_SAMPLES, "a frame of 4 samples holds less noise"
                  " and as much history blur as one of 1: its blends come from its header:"
                  f" {_ALG}#frames-of-several-samples"),
        Departure("albedo_catmull_rom", True, "bilinear resampling blurs the texture the"
                  f" means converge to a little more every frame: {_ALG}"
                  "#sharper-history-resampling-catmull-rom"),
        Departure("moving_feedback_share", 0.0, "where pixels move the feedback blur compounds"
                  f" with the resampling: {_ALG}#feedback-where-pixels-move"),
        Departure("warm_start", 8, "a causal run starts every shot with 1, 2, 3 frames of"
                  " history, the largest part of its loss in video quality: docs/stability.md"
                  "#warm-start"),
        Departure("medium_fill_radius", 4, "a renderer's G-buffer holds no surface where"
                  " its one sample scattered in a medium: fog comes out as raw speckle"
                  " otherwise: docs/algorithm.md#volumes-medium-pixels"),
        Departure("medium_coverage_radius", AUTO_COVERAGE, "the fog's 1-spp light is a few bright"
                  " samples among zeros, which the a-trous darkened by 16 % and spread past the"
                  " fog's edge: docs/algorithm.md#the-mediums-coverage"),
        Departure("medium_motion", True, "a fog does not move as the wall behind it does"
                  " under a camera move: its history came from the wrong place (production"
                  " fog relMSE -18 %): docs/algorithm.md#the-mediums-motion"),
        Departure("atrous_iterations", AUTO_ITERATIONS, "the filter's reach grows with the"
                  f" image (atrous_iterations_for): {_ALG}#the-filters-reach-grows-with-the-image"),
        Departure("taa_jittered", True, "a jittered frame's outline pixel shows one surface"
                  " or the other from frame to frame, the reference their mix: outlines crawl"
                  " and flicker: docs/stability.md#jittered-outlines"),
        Departure("still_emission_mean", True, "a jittered light's outline flips between its"
                  " radiance and nothing from frame to frame, the reference its coverage:"
                  " docs/stability.md#a-still-lights-outline"),
        Departure("taa_alpha", 0.65, "TAA's history lags a moving shadow or light by a frame"
                  " more at 0.5: docs/stability.md#jittered-outlines"),
        Departure("edge_filter", AUTO_PIXEL_FILTER, "frames sampled at pixel centres show"
                  " staircase outlines that crawl as they move, where the renderer's frame"
                  f" is anti-aliased: {_ALG}#outlines-of-centre-sampled-frames-edge-filter"),
        Departure("noisy_outline_weight", 0.25, "a defocused region's 1-spp G-buffer changes"
                  " object from pixel to pixel: the a-trous keeps its samples apart, and the"
                  f" frame stays speckled: {_ALG}#noisy-outlines-defocus"),
        Departure("pixel_filter", AUTO_PIXEL_FILTER, "frames sampled at pixel centres lack the"
                  f" renderer's pixel filter: {_ALG}"
                  "#the-pixel-filter-of-centre-sampled-frames---pixel-filter"),
    ),
    "falcor": (
        Departure("alpha", 0.05, _FALCOR),
        Departure("sigma_luminance", 10.0, _FALCOR),
        Departure("atrous_iterations", 4, _FALCOR),
        Departure("feedback_iteration", 1, _FALCOR),
        Departure("spatial_variance_blur_color", True, _FALCOR),
    ),
}

PRESETS: dict[str, SVGFParams] = {
    name: SVGFParams(**{d.name: d.value for d in departures})
    for name, departures in DEPARTURES.items()
}


# The shorter image side from which each further iteration is used (the paper's 5 from 320).
_ITERATION_SIDES = ((320, 5), (160, 4), (0, 3))


def atrous_iterations_for(params: SVGFParams, height: int, width: int,
                          samples_per_pixel: int = 1) -> int:
    """The a-trous iteration count for an image of ``height`` x ``width`` whose frames hold
    ``samples_per_pixel`` samples (the header's; ``params.samples_per_pixel`` wins when
    not auto).

    An explicit count is kept. ``AUTO_ITERATIONS`` grows the filter's reach with the image:
    the reach doubles with each iteration (about 2^(N+1) pixels), while 1-spp noise per pixel
    does not change with the resolution and scene detail covers more pixels as it grows.
    Measured on the lag sequences rendered at 72, 144 and 288 rows, the best count rose by
    one per doubling (2-3, 3-4, 4): 3 below 160 rows, 4 below 320, and from 320 on the
    paper's 5 (tuned at 720p; more would cost speed at 1080p for little). A frame of N
    samples needs 1/N of the area for the same noise, half the reach per factor 4: one
    iteration fewer per whole factor of 4 (4-15 spp: one, 16-63: two), at least one
    (measured on cycles/roll at 4 spp: docs/algorithm.md#frames-of-several-samples).
    """
    if params.atrous_iterations != AUTO_ITERATIONS:
        return params.atrous_iterations
    side = min(height, width)
    count = next(count for smallest, count in _ITERATION_SIDES if side >= smallest)
    return max(1, count - factors_of_four(params, samples_per_pixel))


def resolved_samples(params: SVGFParams, samples_per_pixel: int) -> int:
    """A frame's samples per pixel as the filter takes them: the header's
    ``samples_per_pixel`` under auto, else ``params.samples_per_pixel``."""
    if params.samples_per_pixel == AUTO_SAMPLES:
        return samples_per_pixel
    return params.samples_per_pixel


def factors_of_four(params: SVGFParams, samples_per_pixel: int) -> int:
    """How many whole factors of 4 a frame's samples per pixel hold
    (:func:`resolved_samples`): 0 for 1-3 samples, 1 for 4-15, 2 for 16-63. Each needs a
    quarter of the area for the same noise, half the reach, which the auto windows follow."""
    samples = resolved_samples(params, samples_per_pixel)
    factors = 0
    while samples >= 4:
        factors += 1
        samples //= 4
    return factors


# The shorter image side from which each wider clamp window is used (as the a-trous count).
_CLAMP_SIDES = ((320, 3), (160, 2), (0, 1))


def history_clamp_radius_for(params: SVGFParams, height: int, width: int) -> int:
    """The history clamp's window radius for an image of ``height`` x ``width``: an
    explicit one is kept; ``AUTO_CLAMP_RADIUS`` grows with the image as the a-trous count
    does (1 below 160 rows, 2 below 320, 3 from 320). The clamp bounds the history by the
    spread of this frame's one-sample values around the pixel: where a surface is lit by
    rare bright samples (indirect light at one sample per pixel) a 3x3 holds only zeros in
    most frames and pulls the history to black, while a wider window holds some of the
    samples. On a small image a wider window reaches across other surfaces and lights
    instead. Measured (docs/algorithm.md#the-history-clamps-window): 72 rows best at 1 (and
    a Blender render at 144), 216 and 360 rows at 2-3."""
    return _by_image_side(params.history_clamp_radius, AUTO_CLAMP_RADIUS, _CLAMP_SIDES,
                          height, width)


# The shorter image side from which each looser luminance stop is used.
_STOP_SIDES = ((640, 3.0), (320, 1.75), (120, 1.0), (0, 0.5))


def luminance_stop_scale_for(params: SVGFParams, height: int, width: int) -> float:
    """The factor on the a-trous luminance stops for an image of ``height`` x ``width``: an
    explicit one is kept; ``AUTO_STOP_SCALE`` loosens the stops as the image grows (0.5 below
    120 rows, 1 below 320, 1.75 below 640, 3 from 640). The stop keeps apart neighbours
    whose luminance differs by more than sigma_l standard deviations of the noise: the noise
    per pixel does not change with the resolution, while a smooth gradient's difference
    between neighbours shrinks as the scene covers more pixels, and each further iteration
    (the count grows with the image too) stops at the compounded product of its weights.
    Measured (docs/algorithm.md#the-luminance-stop-grows-with-the-image): 72 rows best at
    1, 144 and 216 rows at 1.5, 360 rows at 1.75-2, 720 rows at 3-4; with the blurred guide
    (``luminance_guide_blur``, docs/algorithm.md#the-luminance-stops-guide) 72 rows at 0.5,
    216 rows at 1 and 360 rows still at 1.75."""
    return _by_image_side(params.luminance_stop_scale, AUTO_STOP_SCALE, _STOP_SIDES,
                          height, width)


# The shorter image side from which each wider anti-lag window is used.
_ANTILAG_SIDES = ((320, 6), (160, 4), (0, 2))


def antilag_radius_for(params: SVGFParams, height: int, width: int,
                       samples_per_pixel: int = 1) -> int:
    """The anti-lag window's radius (in cells of 2x2 pixels) for an image of ``height`` x
    ``width`` whose frames hold ``samples_per_pixel`` samples: an explicit one is kept;
    ``AUTO_ANTILAG_RADIUS`` is 2 (10x10 pixels) below 160 rows of the shorter side, 4
    (18x18) below 320 and 6 (26x26) from 320, halved (rounded up, at least 1) per whole
    factor of 4 samples (:func:`factors_of_four`: the same noise in a quarter of the area;
    measured on cycles/roll at 4 spp, docs/algorithm.md#frames-of-several-samples). Anti-lag tests
    the history against the window's mean of this frame's samples; the window's noise sets
    how small a change it can tell from noise, and a false alarm restarts the history from
    this frame's mostly dark one-sample values (noise, and a darker frame). On a larger image
    the same change covers more pixels, so a wider window sees it as well with less noise.
    Measured (docs/algorithm.md#the-anti-lag-window-grows-with-the-image): 144 rows best at
    2, 216 rows at 4 (a Blender shot with moving lights on a metal sphere +0.04 JOD), 360
    rows at 4-6, 6 best where the light changes."""
    if params.antilag_radius != AUTO_ANTILAG_RADIUS:
        return params.antilag_radius
    radius = _by_image_side(params.antilag_radius, AUTO_ANTILAG_RADIUS, _ANTILAG_SIDES,
                            height, width)
    for _ in range(factors_of_four(params, samples_per_pixel)):
        radius = max(1, (radius + 1) // 2)
    return radius


_T = TypeVar("_T", int, float)


def _by_image_side(value: _T, auto: _T, sides: tuple[tuple[int, _T], ...], height: int,
                   width: int) -> _T:
    """``value`` where it is not ``auto``; else the value ``sides`` (pairs of the smallest
    shorter side and its value, largest first, the last from 0) gives this image."""
    if value != auto:
        return value
    side = min(height, width)
    return next(chosen for smallest, chosen in sides if side >= smallest)


def medium_coverage_radius_for(params: SVGFParams, height: int, width: int) -> int:
    """The medium coverage's radius for an image of ``height`` x ``width``: an explicit one
    is kept; ``AUTO_COVERAGE`` is 1 below 320 pixels of the shorter side, else one pixel per
    360 of it, at least 2. The coverage of (2 r + 1)^2 samples is the colour the medium's
    light is remodulated by, so its noise shows: a 3x3 one mottles the fog at 360 rows and
    up, while on 128x72 frames (a fog 15 pixels wide) a 5x5 one is already wider than the
    fog's edge. Measured: 72 rows best at 1 (of 1, 2, 3), 216 rows at 1 (video JOD; 2 and 3
    halve the fog's relMSE), 360 rows at 2, 1080 rows smooth from 3 on."""
    if params.medium_coverage_radius != AUTO_COVERAGE:
        return params.medium_coverage_radius
    shorter = min(height, width)
    return 1 if shorter < MEDIUM_COVERAGE_ROWS else max(2, int(shorter / 360 + 0.5))


def params_for_samples(params: SVGFParams, samples_per_pixel: int) -> SVGFParams:
    """The settings for a frame the renderer sampled ``samples_per_pixel`` times per pixel
    (its header's count; ``params.samples_per_pixel`` when not auto).

    A frame of N samples is blended as N one-sample frames of a still scene would be:
    ``alpha`` and ``moments_alpha`` become ``1 - (1 - alpha)^N``. The history's loss
    (resampling blur, lag) is the same per frame while the frame's noise falls with N
    (measured on cycles/roll at 4 spp: docs/algorithm.md#frames-of-several-samples).
    N = 1 gives back ``params`` itself.
    """
    n = resolved_samples(params, samples_per_pixel)
    if n <= 1:
        return params
    return dataclasses.replace(
        params,
        alpha=_frame_blend(params.alpha, n),
        moments_alpha=_frame_blend(params.moments_alpha, n),
    )


def colour_blend_for(params: SVGFParams, samples_per_pixel: int) -> float:
    """The blend of the demodulation colours' running means (``temporal_albedo``) for a
    frame of ``samples_per_pixel`` samples (the header's; ``params.samples_per_pixel`` wins
    when not auto): ``alpha`` for one sample, else the steady-state gain ``K`` of a Kalman
    filter whose measurement noise falls as 1/N while its loss per frame (the means'
    resampling blur, which does not depend on N) stays: ``K^2 / (1 - K) = N alpha^2 /
    (1 - alpha)`` (0.36 at 4 samples and ``alpha`` 0.2, against the light's 0.59). A colour
    changes on a surface only where the texture does; the light's blend (``params_for_samples``)
    also has to follow lights, so it trusts the frame more (measured on cycles/roll at 4
    spp, docs/algorithm.md#frames-of-several-samples)."""
    n = resolved_samples(params, samples_per_pixel)
    if n <= 1 or params.alpha >= 1.0:
        return params.alpha
    ratio = n * params.alpha ** 2 / (1.0 - params.alpha)
    return min(1.0, (math.sqrt(ratio * ratio + 4.0 * ratio) - ratio) / 2.0)


def _frame_blend(alpha: float, samples: int) -> float:
    """The blend factor of a frame worth ``samples`` one-sample frames, each blended at
    ``alpha``: the history keeps ``(1 - alpha)^samples``."""
    return 1.0 - (1.0 - alpha) ** samples


# The preset used when none is named (CLI, evaluation baselines, farm templates).
DEFAULT_PRESET = "default"


def param_fields() -> list[dataclasses.Field[Any]]:
    """The SVGFParams fields, in declaration order."""
    return list(dataclasses.fields(SVGFParams))


def param_range(name: str) -> Range | None:
    """The declared valid range of parameter ``name`` (None: a boolean)."""
    return SVGFParams.__dataclass_fields__[name].metadata["valid"]


def resolve_params(preset: str = DEFAULT_PRESET, **overrides: Any) -> SVGFParams:
    """Start from a preset and apply the overrides that are not None."""
    if preset not in PRESETS:
        raise ValueError(f"unknown preset {preset!r} (choose from {', '.join(PRESETS)})")
    changes = {k: v for k, v in overrides.items() if v is not None}
    unknown = set(changes) - {f.name for f in dataclasses.fields(SVGFParams)}
    if unknown:
        raise ValueError(f"unknown parameter(s): {', '.join(sorted(unknown))}")
    return PRESETS[preset].replace(**changes)


def check_params(p: SVGFParams) -> None:
    """ValueError naming the first parameter of ``p`` outside its declared range, with its
    value and the range."""
    for f in param_fields():
        valid = f.metadata["valid"]
        value = getattr(p, f.name)
        if valid is not None and not valid.contains(value):
            auto = "" if valid.auto is None else f" (auto is {valid.auto:g})"
            raise ValueError(f"{f.name} = {value!r}: must be {valid.text()}{auto}")
