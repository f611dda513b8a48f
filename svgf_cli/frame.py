"""The typed frame that flows from I/O into the filters: structure-of-arrays float32 planes.

Conventions (every producer converts to these, every consumer relies on them):

* colour-like planes are ``(3, H, W)`` float32, C-contiguous, one plane per channel;
* row 0 is the top of the image, x grows right, y grows down;
* ``depth`` is linear view depth, ``(H, W)``; a value ``<= 0`` marks background
  (readers map non-finite or non-positive input depth to 0);
* ``motion`` is ``(2, H, W)`` backward motion in pixels: the surface seen at pixel centre
  ``(x + 0.5, y + 0.5)`` was at ``(x + 0.5 + motion[0], y + 0.5 + motion[1])`` in the
  previous frame;
* ``motion_next`` (optional) is ``(2, H, W)`` motion to the next frame in pixels: the surface
  seen at pixel centre ``p`` is at ``p + motion_next`` in the next frame (a bidirectional
  run's reverse pass reads it; without it the run derives it from the next frame's motion);
* ``mesh_id`` is ``(H, W)`` int32, ``-1`` on background;
* ``signals`` are the noisy radiance signals, each filtered on its own (its own history,
  moments and variance) and summed after filtering. A signal's radiance **excludes**
  emission: ``emission`` (optional, noise-free radiance emitted at the primary hit, e.g.
  Cycles' Emit + Env) is added back once, after filtering. Each signal names its own
  demodulation colour (``Signal.albedo``; several signals may share one array);
* ``albedo`` is the G-buffer albedo (guides, baselines such as OIDN); the filter
  demodulates by each signal's own colour, not by this one;
* ``luminance_weights`` are the RGB -> luminance weights of the data's colour space
  (Rec.709 by default; the reader derives them from the file's chromaticities).

Two constructors cover the common layouts: :meth:`Frame.direct_indirect` (the paper's two
signals, emission inside ``direct`` as ``svgf trace`` writes it) and :meth:`Frame.combined`
(one colour with emission inside it).
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

REC709_LUMINANCE = (0.2126, 0.7152, 0.0722)
# Signal names become EXR layer names (``variance.<name>``) and are stored in history files.
_SIGNAL_NAME = re.compile(r"[A-Za-z0-9_-]+")


def _check_plane(name: str, plane: np.ndarray, shape: tuple[int, ...], dtype: type) -> None:
    if not isinstance(plane, np.ndarray):
        raise ValueError(f"{name}: expected a numpy array, got {type(plane).__name__}")
    if plane.shape != shape:
        raise ValueError(f"{name}: expected shape {shape}, got {plane.shape}")
    if plane.dtype != dtype:
        raise ValueError(f"{name}: expected dtype {np.dtype(dtype)}, got {plane.dtype}")
    if not plane.flags.c_contiguous:
        raise ValueError(f"{name}: planes must be C-contiguous")


@dataclass
class TemporalGradient:
    """A-SVGF temporal gradient samples of one signal (``svgf trace --gradient-samples``):
    at pixels where ``mask`` is 1, the luminance of last frame's sample there (``previous``)
    and of the same surface sample re-shaded in this frame with last frame's random numbers
    (``current``); each (H, W) float32."""

    mask: np.ndarray
    previous: np.ndarray
    current: np.ndarray


@dataclass
class Signal:
    """One noisy radiance signal and the colour it is demodulated by.

    ``radiance`` excludes emission. ``albedo`` is the demodulation colour: the signal is
    filtered as ``radiance / albedo`` where that is a plausible reflectance (every channel
    at most ~1, not black) and as plain radiance elsewhere (see ``filters.modulate``).
    ``gradient`` optionally holds its temporal gradient samples (used by anti-lag).
    ``glossy`` marks light that follows reflections (or refractions) rather than the
    surface: a glossy or transmission lobe. Its reprojected history is not where the
    reflection now is, so the filter clamps it to the current neighbourhood and stops the
    spatial filter at smaller luminance differences (``SVGFParams.glossy_*``).
    ``guide_albedo`` marks a signal demodulated by the G-buffer albedo (the renderer's
    albedo AOV, a guide for denoisers) rather than by the reflectance of this light alone:
    over a dark diffuse base that albedo stays dark where glossy light arrives, so dividing
    by it amplifies that light; such signals get a higher demodulation floor
    (``SVGFParams.guide_albedo_floor``).
    ``mixed`` marks a signal that holds direct and indirect light together (a combined colour,
    or one lobe's whole light): its variance is mostly the indirect light's, far above the
    direct light's, so against it the spatial filter would blur the direct light's shadows
    and shapes; it stops at smaller luminance differences (``SVGFParams.mixed_sigma_luminance``).
    """

    name: str
    radiance: np.ndarray
    albedo: np.ndarray
    gradient: TemporalGradient | None = None
    glossy: bool = False
    guide_albedo: bool = False
    mixed: bool = False


@dataclass
class LightLayer:
    """A light layer the file holds next to its colour (a light pass or a light group), to be
    written denoised under its own channels (``svgf_cli.filters.composable``).

    ``radiance`` is its light in the colour's units, (3, H, W) float32: for a pass the
    renderer stores divided by its colour pass (Cycles' ``DiffDir``...), the stored light
    times ``colour``; ``stored`` is the light as stored (float32), ``colour`` that colour pass
    (None: stored as radiance). ``signal`` names the filtered signal whose light holds it
    (empty: no one signal; its share of all the light). ``channels`` are its R, G, B channel
    names: labels the denoised planes are returned under (the filter knows no files)."""

    channels: tuple[str, str, str]
    radiance: np.ndarray
    stored: np.ndarray
    colour: np.ndarray | None = None
    signal: str = ""
    # The colour pass's R, G, B channel names (written as the colour the filter remodulated
    # by, so that the light x colour rebuild still holds).
    colour_channels: tuple[str, str, str] | None = None


@dataclass
class LightLayers:
    """The light layers of a frame to be written denoised: the light passes the signals are
    built from and the light groups (each the light of some lights, together the colour)."""

    passes: list[LightLayer] = field(default_factory=list)
    groups: list[LightLayer] = field(default_factory=list)
    # The emission passes (Cycles' Emit, Env): they take the light no lobe pass can carry.
    emission: list[LightLayer] = field(default_factory=list)


@dataclass(kw_only=True)
class Frame:
    """One input frame: noisy radiance signals plus the noise-free G-buffer."""

    signals: list[Signal]
    normal: np.ndarray
    depth: np.ndarray
    motion: np.ndarray
    mesh_id: np.ndarray
    albedo: np.ndarray
    emission: np.ndarray | None = None
    luminance_weights: tuple[float, float, float] = field(default=REC709_LUMINANCE)
    motion_next: np.ndarray | None = None
    # The file says its one sample per pixel went through the pixel centre (Cycles at 1 spp),
    # while a converged frame of its renderer averages the pixel filter's footprint.
    centre_sampled: bool = False
    # Samples per pixel the renderer took (its header; 1 when it says nothing): a frame of
    # N samples is worth N one-sample frames in the temporal blends (filters.params).
    samples_per_pixel: int = 1
    # Light passes and light groups to be written denoised (None: none; the Denoiser itself
    # ignores them, `filters.composable.LayeredDenoiser` composes them).
    light: LightLayers | None = None
    # What makes ``light`` when the filter first needs it (None: ``light`` is all there is).
    # `filters.composable.LayeredDenoiser` calls it once its colour filter has let go of its
    # per-frame planes, so the layers' float32 planes are not held beside them.
    light_loader: Callable[[], LightLayers | None] | None = None
    # The output colour, (3, H, W), decided by another pass (the look-ahead warm start of a
    # shot's first frames, ``run.warm_start``): the filter still runs on the frame to build
    # its history, and returns this colour (its light layers add up to it).
    final_colour: np.ndarray | None = None
    # The light of participating media, (3, H, W) (a renderer's volume passes; None: none):
    # where it lights a pixel with no surface, the pixel's sample scattered in the medium
    # (`filters.medium`). The same array as the volume signal's radiance.
    medium: np.ndarray | None = None

    # ----------------------------------------------------------------- constructors
    @classmethod
    def direct_indirect(
        cls,
        direct: np.ndarray,
        indirect: np.ndarray,
        *,
        albedo: np.ndarray,
        normal: np.ndarray,
        depth: np.ndarray,
        motion: np.ndarray,
        mesh_id: np.ndarray,
        emission: np.ndarray | None = None,
        luminance_weights: tuple[float, float, float] = REC709_LUMINANCE,
    ) -> Frame:
        """The paper's two signals, both demodulated by ``albedo``. ``emission`` (when
        given) is part of ``direct``, as ``svgf trace`` writes it; it is taken out of the
        signal here and added back after filtering."""
        return cls(
            signals=[
                Signal("direct", _without(direct, emission), albedo, guide_albedo=True),
                Signal("indirect", indirect, albedo, guide_albedo=True),
            ],
            albedo=albedo, normal=normal, depth=depth, motion=motion, mesh_id=mesh_id,
            emission=emission, luminance_weights=luminance_weights,
        )

    @classmethod
    def combined(
        cls,
        color: np.ndarray,
        *,
        albedo: np.ndarray,
        normal: np.ndarray,
        depth: np.ndarray,
        motion: np.ndarray,
        mesh_id: np.ndarray,
        emission: np.ndarray | None = None,
        luminance_weights: tuple[float, float, float] = REC709_LUMINANCE,
    ) -> Frame:
        """One combined signal named ``color``, demodulated by ``albedo``. ``emission``
        (when given) is part of ``color``; it is taken out and added back after filtering."""
        return cls(
            signals=[Signal("color", _without(color, emission), albedo, guide_albedo=True,
                            mixed=True)],
            albedo=albedo, normal=normal, depth=depth, motion=motion, mesh_id=mesh_id,
            emission=emission, luminance_weights=luminance_weights,
        )

    # ----------------------------------------------------------------- accessors
    @property
    def height(self) -> int:
        return int(self.depth.shape[0])

    @property
    def width(self) -> int:
        return int(self.depth.shape[1])

    @property
    def names(self) -> tuple[str, ...]:
        """The signal names, in order."""
        return tuple(s.name for s in self.signals)

    def release_filtered_planes(self) -> None:
        """Let go of the planes only a colour's filter reads: each signal's radiance,
        demodulation colour and gradient samples (its name and flags stay, its planes
        become empty), the medium and the emission. For a caller that composes the light
        layers once the colour is filtered and consumes the frame
        (`filters.composable.LayeredDenoiser`): those planes need not live until then."""
        empty = np.empty((3, 0, 0), dtype=np.float32)
        self.signals = [replace(s, radiance=empty, albedo=empty, gradient=None)
                        for s in self.signals]
        self.medium = None
        self.emission = None

    def signal(self, name: str) -> Signal:
        """The signal called ``name`` (ValueError if there is none)."""
        for s in self.signals:
            if s.name == name:
                return s
        raise ValueError(f"frame has no signal {name!r} (it has {', '.join(self.names)})")

    def total_radiance(self) -> np.ndarray:
        """The unfiltered radiance the signals stand for: their sum plus the emission."""
        total = np.zeros((3, self.height, self.width), dtype=np.float32)
        for s in self.signals:
            total += s.radiance
        if self.emission is not None:
            total += self.emission
        return total

    def validate(self) -> None:
        """Raise ValueError when a plane has the wrong shape, dtype or layout, or the
        signals or luminance weights are malformed (values are the Denoiser's business)."""
        if not isinstance(self.depth, np.ndarray) or self.depth.ndim != 2:
            raise ValueError("depth: expected an (H, W) array")
        h, w = self.depth.shape
        f32 = np.float32
        _check_plane("depth", self.depth, (h, w), f32)
        _check_plane("albedo", self.albedo, (3, h, w), f32)
        _check_plane("normal", self.normal, (3, h, w), f32)
        _check_plane("motion", self.motion, (2, h, w), f32)
        _check_plane("mesh_id", self.mesh_id, (h, w), np.int32)
        if self.emission is not None:
            _check_plane("emission", self.emission, (3, h, w), f32)
        if self.motion_next is not None:
            _check_plane("motion_next", self.motion_next, (2, h, w), f32)
        if self.medium is not None:
            _check_plane("medium", self.medium, (3, h, w), f32)
        if self.final_colour is not None:
            _check_plane("final_colour", self.final_colour, (3, h, w), f32)
        if not self.signals:
            raise ValueError("frame has no signals")
        seen: set[str] = set()
        for s in self.signals:
            if not isinstance(s, Signal):
                raise ValueError(f"signals: expected Signal objects, got {type(s).__name__}")
            if not isinstance(s.name, str) or not _SIGNAL_NAME.fullmatch(s.name):
                raise ValueError(
                    f"signal name {s.name!r}: use letters, digits, '_' or '-' (it names layers)"
                )
            if s.name in seen:
                raise ValueError(f"signal name {s.name!r} is used twice")
            seen.add(s.name)
            _check_plane(f"{s.name} radiance", s.radiance, (3, h, w), f32)
            _check_plane(f"{s.name} albedo", s.albedo, (3, h, w), f32)
            if s.gradient is not None:
                for part in ("mask", "previous", "current"):
                    _check_plane(f"{s.name} gradient {part}", getattr(s.gradient, part),
                                 (h, w), f32)
        weights = tuple(self.luminance_weights)
        if len(weights) != 3 or not all(
            isinstance(v, (int, float, np.floating)) and math.isfinite(v) and v >= 0.0
            for v in weights
        ):
            raise ValueError(
                f"luminance_weights {self.luminance_weights!r}: need three finite weights >= 0"
            )
        if abs(sum(weights) - 1.0) > 0.01:
            raise ValueError(
                f"luminance_weights {self.luminance_weights!r}: must sum to 1 (they sum to"
                f" {sum(weights):.4g})"
            )


def _without(radiance: np.ndarray, emission: np.ndarray | None) -> np.ndarray:
    """``radiance - emission`` as a fresh float32 plane, or ``radiance`` itself."""
    if emission is None:
        return radiance
    return np.ascontiguousarray(np.subtract(radiance, emission, dtype=np.float32))


@dataclass
class DenoisedFrame:
    """What the denoiser returns for one frame.

    ``color`` is the final ``(3, H, W)`` radiance (signals filtered, remodulated and summed,
    emission added). ``layers`` holds optional debug planes keyed by EXR channel name, each
    ``(H, W)`` float32 (``<signal>.R/G/B``, ``variance.<signal>``,
    ``history_length.<signal>``, ``radiance_mode.<signal>``). ``counts`` reports what the
    value policy and the demodulation did to this frame (see :data:`COUNT_KEYS`);
    :meth:`warnings` turns the problems among them into one-line messages.
    """

    color: np.ndarray
    layers: dict[str, np.ndarray]
    counts: dict[str, int] = field(default_factory=dict)
    # Denoised light layers, (H, W) float32 per channel name (`Frame.light`'s labels).
    light: dict[str, np.ndarray] = field(default_factory=dict)
    # The emission added back to ``color``: the frame's, less what a stage took into a
    # signal to be filtered (the medium pixels' emission: filters.stages.fill_medium).
    emission: np.ndarray | None = None
    # (H, W) bool: the pixels whose G-buffer was a medium's (filters.stages.fill_medium).
    medium: np.ndarray | None = None
    # (H, W) bool: the pixels whose emission added back is a still light's mean over frames,
    # not the frame's (filters.stages.emission_mean); None: none.
    emission_averaged: np.ndarray | None = None
    # The frame's G-buffer as the filter used it, in a frame without signals (None unless
    # the filter was asked for it: `filters.denoiser.Denoiser.gbuffer_output`).
    gbuffer: Frame | None = None
    # The noisy outlines' exchanges made on ``color`` after the emission was added
    # (`filters.edge_filter.OutlineSpill`; None: none): the light layers make the same.
    outline_spill: Any = None

    def warnings(self) -> list[str]:
        """One message per problem counted in this frame (empty when there is none)."""
        return count_warnings(self.counts)


# Keys of DenoisedFrame.counts. Totals are always present; per-signal keys end in
# ".<signal>"; per-plane breakdowns ("nonfinite.<plane>", "extreme.<plane>") appear only
# when non-zero.
COUNT_KEYS = {
    "nonfinite": "non-finite input values (NaN/Inf) replaced: radiance, emission, albedo and"
    " normals by 0, depth by background, motion by 'no history'",
    "extreme": "finite input values beyond +-VALUE_LIMIT (1e15) replaced: radiance,"
    " emission and normals by 0, depth by background",
    "clamped.<signal>": "demodulated values clamped to +-VALUE_LIMIT (large radiance over a"
    " small albedo)",
    "radiance_mode.<signal>": "surface pixels filtered as radiance, not demodulated (black or"
    " implausible demodulation colour)",
    "implausible_albedo.<signal>": "of those, pixels whose demodulation colour exceeds a"
    " reflectance (a channel above 1 + tolerance)",
    "reflected_light.<signal>": "surface pixels of a glossy signal filtered as radiance"
    " because the G-buffer albedo marks a reflected light there (not counted as implausible;"
    " information, not a problem)",
    "reflected_albedo.<signal>": "surface pixels of a glossy signal demodulated by the"
    " G-buffer albedo because their object reflects a sharp image there (information, not a"
    " problem)",
    "history_resets": "pixel histories reset because a stage produced a non-finite value",
    "history_gain": "(signal, pixel) histories rescaled because the light around them changed"
    " by one factor (a light switched or dimmed; information, not a problem)",
    "antilag": "(signal, pixel) histories shortened by anti-lag because the frame no longer"
    " matched them (information, not a problem)",
    "fireflies_spread.<signal>": "current samples above their history's m1 + k sigma and 4x"
    " their second-brightest neighbour, bounded with the excess shared over the surface"
    " around them (information, not a problem)",
    "despiked.<signal>": "output pixels brought down to the despike ratio times their"
    " second-brightest neighbour (fireflies the spatial filter kept; information, not a"
    " problem)",
    "despiked_lone": "output pixels whose filtering mode no neighbour shares, brought down"
    " to the despike ratio times their second-brightest output neighbour",
    "medium_still": "medium pixels (fog, smoke) whose history is reprojected with no motion,"
    " not the motion of the surface behind them: the medium's light follows none better"
    " (information, not a problem)",
}


def count_warnings(counts: dict[str, int]) -> list[str]:
    """Human-readable lines for the problem counts (radiance-mode pixels from black
    surfaces are normal and not reported; implausible demodulation colours are)."""
    lines: list[str] = []

    def breakdown(prefix: str) -> str:
        parts = [f"{k[len(prefix) + 1:]} {v}" for k, v in sorted(counts.items())
                 if k.startswith(prefix + ".") and v]
        return f" ({', '.join(parts)})" if parts else ""

    if counts.get("nonfinite", 0):
        lines.append(f"{counts['nonfinite']} non-finite input value(s) cleaned"
                     f"{breakdown('nonfinite')}")
    if counts.get("extreme", 0):
        lines.append(f"{counts['extreme']} input value(s) beyond +-1e15 replaced by 0"
                     f"{breakdown('extreme')}")
    for key, value in sorted(counts.items()):
        if not value:
            continue
        if key.startswith("clamped."):
            lines.append(f"signal {key[8:]}: {value} demodulated value(s) clamped to +-1e15")
        elif key.startswith("implausible_albedo."):
            lines.append(
                f"signal {key[19:]}: {value} pixel(s) with a demodulation colour above 1"
                " filtered as radiance (not a reflectance)"
            )
    if counts.get("history_resets", 0):
        lines.append(f"{counts['history_resets']} pixel history(ies) reset after a non-finite"
                     " intermediate value")
    return lines
