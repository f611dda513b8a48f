"""Every buffer role of the filter, its shape, and which roles share memory (and when).

All buffers are float32 structure-of-arrays planes (the mode mask uint16), allocated once per
resolution and signal count and reused, so memory does not grow with the sequence length.
Shapes are given for S signals of H x W pixels.

**Permanent** (:data:`HISTORY_SHAPES`): the history, kept between frames; ``state()`` saves
exactly these. Besides them a filter keeps the temporal albedo's colour means (fresh arrays
per frame: last frame's are let go once this frame's are made), TAA's previous output and,
in a bidirectional reverse pass, the forward pass's colour means (``combine_albedo``).

**Per frame** (:data:`ROLES`): the :class:`Workspace` hands out a plane per role on first
use, so optional stages cost no memory unless enabled. A role listed in :data:`SHARING`
lives in another role's memory for the stages named there (the lifetimes are stage names of
``filters.pipeline``; ``tests/test_filters_pipeline.py`` checks no plane is handed to two
live roles at once):

- the reprojection's thresholds live in the variance planes until the variance is estimated;
- last frame's colour, moments and length, dead once reprojected, lend their memory until
  ``store_history`` replaces them (:func:`lend_stale_history`): an a-trous colour buffer,
  the luminance guides, a variance buffer and (before the blend) the anti-lag scratch;
- the a-trous ping-pong takes its outputs from :data:`ILLUMINATION_SCRATCH`, in that order,
  skipping the buffers in use: the demodulated frame (dead once accumulated) comes first;
- firefly spreading (before the blend) and despike (after the a-trous) share one plane;
- ``store_history`` swaps this frame's planes with the stale history (no copies).

At 1080p the resident set including the history is 344 MB with two signals and 473 MB with
three.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from svgf_cli.filters.antilag import cell_shape, scratch_shape
from svgf_cli.filters.params import SVGFParams

F32 = np.float32
Shape = Callable[[int, int, int], tuple[int, ...]]

# The persistent history: name -> (shape given (S, H, W), dtype).
HISTORY_SHAPES: dict[str, tuple[Shape, type]] = {
    "history_illumination": (lambda s, h, w: (s, 3, h, w), F32),
    "history_moments": (lambda s, h, w: (s, 2, h, w), F32),
    "history_length": (lambda s, h, w: (s, h, w), F32),
    "history_mode": (lambda s, h, w: (h, w), np.uint16),
    "prev_depth": (lambda s, h, w: (h, w), F32),
    "prev_normal": (lambda s, h, w: (3, h, w), F32),
    "prev_mesh_id": (lambda s, h, w: (h, w), np.int32),
}

# Illumination-shaped (S, 3, H, W) scratch roles, in order of preference for a-trous outputs.
# "stale_colour" is last frame's colour history, dead once reprojected.
ILLUMINATION_SCRATCH = (
    "demodulated", "accumulated", "stale_colour", "spare_a", "spare_b", "spare_c",
)

# Per-frame roles: name -> (shape given (S, H, W), dtype). "emitter_colour.<i>" is (3, H, W).
ROLES: dict[str, tuple[Shape, type]] = {
    **{name: ((lambda s, h, w: (s, 3, h, w)), F32) for name in ILLUMINATION_SCRATCH},
    "normal": (lambda s, h, w: (3, h, w), F32),
    "ddx": (lambda s, h, w: (h, w), F32),
    "ddy": (lambda s, h, w: (h, w), F32),
    "mode": (lambda s, h, w: (h, w), np.uint16),
    # resampled and then (in place) accumulated moments and history length
    "moments": (lambda s, h, w: (s, 2, h, w), F32),
    "history_length": (lambda s, h, w: (s, h, w), F32),
    "combined_moments": (lambda s, h, w: (s, 2, h, w), F32),
    "combined_length": (lambda s, h, w: (s, h, w), F32),
    "variance": (lambda s, h, w: (s, h, w), F32),
    "variance_a": (lambda s, h, w: (s, h, w), F32),
    "variance_b": (lambda s, h, w: (s, h, w), F32),
    # the reprojection's normal threshold where "variance" has no second plane
    "normal_width": (lambda s, h, w: (h, w), F32),
    "guide_luminance": (lambda s, h, w: (s, h, w), F32),
    "guide_inverse_scale": (lambda s, h, w: (s, h, w), F32),
    "taa": (lambda s, h, w: (3, h, w), F32),
    "despike_luminance": (lambda s, h, w: (h, w), F32),
    "reflected_lights": (lambda s, h, w: (h + 2, w + 2), np.uint8),
    "reflected_lights_scratch": (lambda s, h, w: (2, h, w), np.uint8),
    "antilag_scratch": (lambda s, h, w: scratch_shape(s, h, w), F32),
    "antilag_lambda": (lambda s, h, w: (s, *cell_shape(h, w)), F32),
}


@dataclass(frozen=True)
class Share:
    """``role`` lives in ``host``'s memory from the first stage in ``since`` that a pipeline
    runs to the last stage in ``until`` that it runs (both inclusive)."""

    role: str
    host: str
    since: tuple[str, ...]
    until: tuple[str, ...]
    note: str
    when: str = ""  # a setting that must be on ("name") or off ("!name") for this share


SPATIAL = ("variance", "pass_history")
ATROUS = ("atrous", "pass_history")
LAST_ATROUS = ("pass_history", "atrous")
# The stages that resample last frame's history (a turning object's a second time).
RESAMPLING = ("reproject", "object_history")

# Who lives in whose memory, and when. A host's own lifetime is listed as a share of itself.
SHARING: tuple[Share, ...] = (
    Share("depth_slope", "variance[0]", ("gradients",), RESAMPLING,
          "the reprojection's depth threshold"),
    Share("normal_width", "variance[1]", ("gradients",), RESAMPLING,
          "the reprojection's normal threshold (its own plane with one signal)"),
    Share("reverse_length", "variance_b", ("combine",), ("accumulate",),
          "the reverse pass's shortened own history length"),
    Share("variance", "variance[0]", SPATIAL, ("pass_history", "remodulate"),
          "the variance itself"),
    Share("variance", "variance[1]", SPATIAL, ("pass_history", "remodulate"),
          "the variance itself"),
    Share("variance_b", "variance_b", ATROUS, LAST_ATROUS, "a-trous variance ping-pong"),
    Share("history_illumination", "history_illumination", ("values",), RESAMPLING,
          "last frame's colour history"),
    Share("antilag_scratch", "history_illumination", ("history_gain", "antilag"),
          ("antilag",), "the history gain's and anti-lag's statistics, a prefix of the stale"
          " colour"),
    Share("stale_colour", "history_illumination", ATROUS, ("store_history",),
          "an a-trous colour buffer"),
    Share("history_moments", "history_moments", ("values",), RESAMPLING,
          "last frame's moments"),
    Share("guide_luminance", "history_moments", ATROUS, LAST_ATROUS,
          "first half: the a-trous luminance guide"),
    Share("history_length", "history_length", ("values",), RESAMPLING,
          "last frame's history length"),
    Share("variance_a", "history_length", ATROUS, LAST_ATROUS, "a-trous variance ping-pong"),
    Share("demodulated", "demodulated", ("demodulate",), ("accumulate",),
          "this frame's demodulated illumination"),
    Share("atrous_output", "demodulated", ATROUS, ("pass_history", "remodulate"),
          "the first a-trous output (ILLUMINATION_SCRATCH order)",
          when="!spatial_variance_blur_color"),
    Share("blurred_colour", "demodulated", SPATIAL, ATROUS,
          "the colour blur's output, entering the a-trous (whose outputs then start at"
          " accumulated)", when="spatial_variance_blur_color"),
    Share("clamped", "spare_a", ("firefly_clamp",), ("accumulate",),
          "the firefly-clamped frame", when="firefly_clamp"),
    Share("combined", "spare_a", ("combine",), ("remodulate",),
          "the reverse pass's combination", when="!firefly_clamp"),
    Share("combined", "spare_b", ("combine",), ("remodulate",),
          "the reverse pass's combination (spare_a holds the clamped frame)",
          when="firefly_clamp"),
    Share("fireflies_luminance", "despike_luminance", ("spread_fireflies",),
          ("spread_fireflies",), "firefly spreading's luminance"),
    Share("despike_luminance", "despike_luminance", ("despike",), ("despike_lone",),
          "despike's luminance"),
)


def lend_stale_history(stale: dict[str, np.ndarray], s: int, h: int,
                       w: int) -> dict[str, np.ndarray]:
    """The scratch roles last frame's history lends once reprojected (:data:`SHARING`):
    3S + S + 2S planes the workspace no longer needs."""
    colour = stale["history_illumination"]
    # (S, 2, H, W) moments as two contiguous (S, H, W) halves (scratch: layout is free).
    halves = stale["history_moments"].reshape(2, s, h, w)
    borrowed = {
        "stale_colour": colour,
        "guide_luminance": halves[0],
        "guide_inverse_scale": halves[1],
        "variance_a": stale["history_length"],
    }
    shape = scratch_shape(s, h, w)
    size = int(np.prod(shape))
    if size <= colour.size:  # always but for images of a few pixels
        borrowed["antilag_scratch"] = colour.reshape(-1)[:size].reshape(shape)
    return borrowed


def fresh_history(s: int, h: int, w: int) -> dict[str, np.ndarray]:
    """A zeroed set of :data:`HISTORY_SHAPES` arrays."""
    return {key: np.zeros(shape_of(s, h, w), dtype=dtype)
            for key, (shape_of, dtype) in HISTORY_SHAPES.items()}


@dataclass
class Workspace:
    """Per-frame planes for one resolution and signal count (reused every frame), one per
    role of :data:`ROLES`, allocated on first use."""

    height: int
    width: int
    num_signals: int
    planes: dict[str, np.ndarray] = field(default_factory=dict)

    def shape(self, name: str) -> tuple[tuple[int, ...], type]:
        h, w, s = self.height, self.width, self.num_signals
        if name.startswith("emitter_colour."):
            return (3, h, w), F32
        shape_of, dtype = ROLES[name]
        return shape_of(s, h, w), dtype

    def __getitem__(self, name: str) -> np.ndarray:
        plane = self.planes.get(name)
        if plane is None:
            shape, dtype = self.shape(name)
            plane = np.zeros(shape, dtype=dtype)
            self.planes[name] = plane
        return plane


def free_scratch(protected: tuple[str, ...], *taken: str) -> str:
    """The first :data:`ILLUMINATION_SCRATCH` role neither ``taken`` nor ``protected``."""
    for name in ILLUMINATION_SCRATCH:
        if name not in taken and name not in protected:
            return name
    raise AssertionError("out of scratch buffers")


def combined_role(firefly_clamp: float) -> str:
    """Where a reverse pass combines the forward history's colour: a spare buffer that is
    neither the pass's own accumulation nor the demodulated frame (which the firefly clamp
    puts in ``spare_a``)."""
    return "spare_b" if firefly_clamp > 0.0 else "spare_a"


def live_ranges(stages: Sequence[str], params: SVGFParams) -> list[tuple[Share, int, int]]:
    """Each :data:`SHARING` entry that applies to a pipeline of ``stages`` (names, in order)
    with ``params``, with the first and last stage index it is live (inclusive)."""
    ranges = []
    for share in SHARING:
        if share.when:
            setting = share.when.lstrip("!")
            if bool(getattr(params, setting)) == share.when.startswith("!"):
                continue
        since = [stages.index(name) for name in share.since if name in stages]
        until = [stages.index(name) for name in share.until if name in stages]
        if since and until:
            ranges.append((share, min(since), max(until)))
    return ranges
