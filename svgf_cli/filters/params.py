"""SVGF parameters: one dataclass with the paper's defaults, documented once.

Every field's ``metadata["help"]`` is the single place its meaning is written down; the CLI
builds one ``--option`` per field from it (``svgf_cli.commands.options``), the README table
is generated from the same text, and the resolved values are stored in every output's
metadata as ``svgf/params``.
"""

from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass, field
from typing import Any

# ``atrous_iterations`` value that picks the count from the image size.
AUTO_ITERATIONS = -1
# ``pixel_filter`` from the frame's header (svgf_cli.filters.pixel_filter).
AUTO_PIXEL_FILTER = -1.0


def _p(default: Any, help: str, **extra: Any) -> Any:
    return field(default=default, metadata={"help": help, **extra})


@dataclass(frozen=True)
class SVGFParams:
    """Resolved SVGF parameters. Defaults are Schied et al. 2017 (``--preset paper``)."""

    # Temporal accumulation (paper section 4.1).
    alpha: float = _p(0.2, "Minimum colour blend factor; alpha = max(alpha, 1/history_length).")
    moments_alpha: float = _p(0.2, "Minimum blend factor of the luminance moments.")
    history_cap: int = _p(32, "Maximum history length in frames.")
    temporal: bool = _p(True, "Reuse history through motion vectors (off: every frame cold).")
    depth_tolerance: float = _p(
        10.0,
        "Reprojection rejects a tap when |z_prev - z| > tolerance * (depth_gradient"
        " + depth_slack * z).",
    )
    depth_slack: float = _p(
        0.002,
        "Depth-relative slack of the reprojection depth test (scale-free stand-in for"
        " Falcor's absolute 0.01).",
    )
    normal_tolerance: float = _p(
        16.0, "Reprojection rejects a tap when |n - n_prev| > tolerance * (normal_gradient + 0.01)."
    )
    history_catmull_rom: bool = _p(
        False,
        "Resample the reprojected colour history and moments with a Catmull-Rom spline over"
        " the 4x4 taps (clamped to the bilinear taps' range) where all 16 pass the"
        " reprojection tests, bilinear elsewhere: bilinear resampling blurs the history a"
        " little more every frame.",
    )
    bidirectional: bool = _p(
        False,
        "Offline: also run the filter backwards in time and combine both passes' histories"
        " per pixel before the spatial filter (frames after the current one count too;"
        " about twice the work; docs/bidirectional.md).",
    )
    # Variance estimation (paper section 4.2).
    variance_history_threshold: int = _p(
        4, "Below this history length the variance is estimated spatially (7x7 bilateral)."
    )
    spatial_variance_radius: int = _p(3, "Radius of the spatial variance estimate (3 = 7x7).")
    spatial_variance_sigma_luminance: float = _p(
        10.0,
        "Weak luminance edge-stop of the spatial variance estimate, relative to the pair's"
        " mean luminance: exp(-|dl| / (sigma * mean l)) (Falcor's raw phiColor at l = 1,"
        " the same at every brightness).",
    )
    spatial_variance_blur_color: bool = _p(
        False,
        "Also replace short-history colour by the spatially filtered colour (Falcor; the"
        " paper filters only the variance).",
    )
    # Anti-lag (filters/antilag.py): history that no longer matches the frame is shortened.
    antilag: bool = _p(
        False,
        "Shorten the history where it disagrees with the current frame beyond the noise"
        " (moving lights and shadows, lights switched or dimmed, moving reflections).",
    )
    antilag_radius: int = _p(
        2, "Anti-lag window radius in cells of 2x2 pixels (2 = 5x5 cells, 10x10 pixels)."
    )
    antilag_sigma: float = _p(
        3.5,
        "Anti-lag significance: the history is stale where it differs from the frame by more"
        " than this many standard errors of the window's noise.",
    )
    antilag_spatial_samples: float = _p(
        64.0,
        "Anti-lag strength: pixels the spatial filter is assumed to average; the current frame"
        " gets weight b^2 / (b^2 + var / N) for a stale history of bias b.",
    )
    antilag_tolerance: float = _p(
        0.02, "Anti-lag relative tolerance: history within this fraction of the frame is kept."
    )
    antilag_gradients: bool = _p(
        True,
        "Anti-lag also uses temporal gradient samples (A-SVGF) when the input has them"
        " (svgf trace --gradient-samples).",
    )
    # Glossy signals (Signal.glossy: reflections and refractions move with what they show,
    # not with the surface, so their reprojected history is unreliable).
    glossy_history_clamp: float = _p(
        0.0,
        "Clamp a glossy signal's reprojected history to the current 3x3 mean +- k*sigma"
        " (0 = as history_clamp).",
    )
    glossy_sigma_luminance: float = _p(
        0.0,
        "sigma_l of glossy signals: reflections carry detail the spatial filter must keep"
        " (0 = the same as sigma_luminance).",
    )
    mixed_sigma_luminance: float = _p(
        0.0,
        "sigma_l of signals holding direct and indirect light together (a combined colour, one"
        " lobe's whole light): their variance is the indirect light's, which would blur the"
        " direct light's detail (0 = the same as sigma_luminance; glossy signals keep"
        " glossy_sigma_luminance).",
    )
    glossy_emitter_radiance: bool = _p(
        False,
        "Filter a glossy signal as radiance where the G-buffer albedo is no reflectance"
        " (brightest channel above 1.05: Cycles' Denoising Albedo holds the light's emission"
        " where a specular path reached a light) at the pixel and at a neighbour: a reflected"
        " light is filtered with the pixels that also see it, not blurred into the surface"
        " around it.",
    )
    # A-trous wavelet filter (paper section 4.3).
    atrous_iterations: int = _p(
        5,
        "Number of a-trous iterations (steps 1, 2, 4, ...); 0 = none; auto (-1 in"
        " svgf/params) = from the image's shorter side: 3 below 160 pixels, 4 below 320,"
        " else 5.",
    )
    feedback_iteration: int = _p(
        0, "A-trous iteration whose output becomes the colour history (-1 = unfiltered)."
    )
    moving_feedback_share: float = _p(
        1.0,
        "Share of the feedback iteration's output in the colour history where the pixel"
        " moves (the rest: the unfiltered accumulation; 1 = the paper's feedback everywhere).",
    )
    sigma_luminance: float = _p(4.0, "sigma_l: luminance edge-stopping against sqrt(variance).")
    sigma_normal: float = _p(128.0, "sigma_n: exponent of the normal edge-stopping weight.")
    sigma_depth: float = _p(1.0, "sigma_z: depth edge-stopping against the depth gradient.")
    # Demodulation (paper section 4).
    albedo_epsilon: float = _p(
        1e-3,
        "Demodulation floor: a signal's colour below it in every channel is black and filtered"
        " as radiance; otherwise each channel is floored at max(albedo_epsilon, 0.02 * the"
        " brightest channel).",
    )
    guide_albedo_floor: float = _p(
        0.0,
        "Demodulation floor of signals demodulated by the G-buffer albedo (a combined colour"
        " over the renderer's albedo AOV): glossy light over a dark diffuse base is not"
        " modulated by that albedo, and dividing by it amplifies the light (0 ="
        " albedo_epsilon).",
    )
    temporal_albedo: bool = _p(
        False,
        "Remodulate each signal (not glossy ones) by its demodulation colour's running mean"
        " over frames"
        " (reprojected, clamped to the current 3x3 range; without history a 3x3 Gaussian"
        " mean): at 1 spp a pixel's colour is one sample of a texture edge, a renderer's"
        " reference the pixel-filtered mean (off for a renderer whose references are point"
        " samples, as svgf trace's are by default: the mean only blurs them).",
    )
    albedo_catmull_rom: bool = _p(
        False,
        "Resample the temporal albedo's colour means with a Catmull-Rom spline over the 4x4"
        " taps (clamped to the bilinear taps' range) where all 16 pass its tests, bilinear"
        " elsewhere: bilinear resampling blurs the texture the means converge to a little"
        " more every frame.",
    )
    # Optional extras from the lecture notes; all off unless asked.
    firefly_clamp: float = _p(
        0.0,
        "Clamp input luminance to mean + k*sigma of the 8 neighbours before accumulation"
        " (0 = off).",
    )
    spread_fireflies: float = _p(
        0.0,
        "Before accumulation, a sample above both its history's m1 + k*sigma and 4x its"
        " second-brightest same-mode neighbour is bounded there and its excess shared over the"
        " same surface in the 9x9 around it (energy kept; glossy signals excepted; 0 = off).",
    )
    history_clamp: float = _p(
        0.0,
        "Clamp the reprojected history to the 3x3 mean +- k*sigma of the current frame,"
        " its luminance moments scaled with it (0 = off; glossy signals: glossy_history_clamp).",
    )
    despike: float = _p(
        0.0,
        "Output guard: a filtered pixel brighter than this many times its second-brightest"
        " same-mode neighbour (any neighbour, in the output, for a pixel whose mode none"
        " shares) is brought down to that bound (fireflies the a-trous kept; 0 = off).",
    )
    pixel_filter: float = _p(
        0.0,
        "Neighbour weight w of a [w, 1-2w, w] kernel per axis applied to the output without"
        " its emission: the renderer's pixel filter, which frames sampled at pixel centres"
        " lack (0 = off; auto (-1 in svgf/params) = 0.05 where the header says the frame is"
        " one sample through the pixel centre, Cycles at 1 spp, else off).",
    )
    taa: bool = _p(
        False,
        "Temporal anti-aliasing of the output at object outlines (the paper's last step):"
        " the previous output, Catmull-Rom resampled and clipped to the current 3x3, blended"
        " in where a jittered sample flips between two surfaces.",
    )
    taa_alpha: float = _p(0.5, "The current output's share in the TAA blend (before the"
                               " luminance weighting).")

    def to_json(self) -> str:
        """Stable JSON of every field (sorted keys), stored in output metadata."""
        return json.dumps(dataclasses.asdict(self), sort_keys=True)

    def replace(self, **changes: Any) -> SVGFParams:
        return dataclasses.replace(self, **changes)


PRESETS: dict[str, SVGFParams] = {
    # Schied et al. 2017: alpha 0.2, sigma_l 4, sigma_n 128, sigma_z 1, 5 iterations,
    # first iteration fed back as history.
    "paper": SVGFParams(),
    # The recommended set (measured in docs/results.md): the paper's filter plus anti-lag, a
    # loose history clamp against outliers (k = 3), the glossy rules (reflected lights
    # filtered as radiance: docs/signals.md), a tighter luminance
    # stop for the short-history spatial variance (0.5: fireflies and lit/shadowed
    # neighbours no longer inflate it into an over-blur), firefly spreading (k = 10),
    # despike (ratio 2),
    # demodulation by the G-buffer albedo only where it is at least 0.1, the temporal
    # albedo with its means resampled by Catmull-Rom (docs/algorithm.md), the feedback
    # a-trous output kept as history only where pixels stand still (where they move the
    # blur compounds with the resampling: docs/algorithm.md), and an a-trous reach that
    # grows with the image (atrous_iterations_for).
    "default": SVGFParams(antilag=True, history_clamp=3.0, glossy_history_clamp=1.0,
                          glossy_sigma_luminance=1.0, glossy_emitter_radiance=True,
                          mixed_sigma_luminance=2.5, spatial_variance_sigma_luminance=0.5,
                          despike=2.0, spread_fireflies=10.0, guide_albedo_floor=0.1,
                          temporal_albedo=True, albedo_catmull_rom=True,
                          moving_feedback_share=0.0, atrous_iterations=AUTO_ITERATIONS,
                          pixel_filter=AUTO_PIXEL_FILTER),
    # Falcor's SVGFPass defaults (see shared/research/svgf-anchors.md, section 2).
    "falcor": SVGFParams(
        alpha=0.05,
        moments_alpha=0.2,
        sigma_luminance=10.0,
        atrous_iterations=4,
        feedback_iteration=1,
        spatial_variance_blur_color=True,
    ),
}


# The shorter image side from which each further iteration is used (the paper's 5 from 320).
_ITERATION_SIDES = ((320, 5), (160, 4), (0, 3))


def atrous_iterations_for(params: SVGFParams, height: int, width: int) -> int:
    """The a-trous iteration count for an image of ``height`` x ``width``.

    An explicit count is kept. ``AUTO_ITERATIONS`` grows the filter's reach with the image:
    the reach doubles with each iteration (about 2^(N+1) pixels), while 1-spp noise per pixel
    does not change with the resolution and scene detail covers more pixels as it grows.
    Measured on the lag sequences rendered at 72, 144 and 288 rows, the best count rose by
    one per doubling (2-3, 3-4, 4): 3 below 160 rows, 4 below 320, and from 320 on the
    paper's 5 (tuned at 720p; more would cost speed at 1080p for little).
    """
    if params.atrous_iterations != AUTO_ITERATIONS:
        return params.atrous_iterations
    side = min(height, width)
    return next(count for smallest, count in _ITERATION_SIDES if side >= smallest)


# The preset used when none is named (CLI, evaluation baselines, farm templates).
DEFAULT_PRESET = "default"


def resolve_params(preset: str = DEFAULT_PRESET, **overrides: Any) -> SVGFParams:
    """Start from a preset and apply the overrides that are not None."""
    if preset not in PRESETS:
        raise ValueError(f"unknown preset {preset!r} (choose from {', '.join(PRESETS)})")
    changes = {k: v for k, v in overrides.items() if v is not None}
    unknown = set(changes) - {f.name for f in dataclasses.fields(SVGFParams)}
    if unknown:
        raise ValueError(f"unknown parameter(s): {', '.join(sorted(unknown))}")
    return PRESETS[preset].replace(**changes)
