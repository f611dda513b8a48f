"""The SVGF denoiser: owns the history buffers and runs the stages in order.

Per frame, three phases (one method each, so a bidirectional run can drive them apart):

1. temporal accumulation (``_accumulate_temporally``): input values (``values``) -> geometry
   gradients -> demodulate every signal, with its per-pixel mode (+ optional firefly clamp)
   -> reproject every signal's history -> the pre-accumulation hook (optional history
   clamp, anti-lag) -> firefly spreading -> accumulate;
2. spatial filtering (``_filter_spatially``): variance -> a-trous iterations over groups
   of two or three signals; the ``feedback_iteration`` output becomes next frame's colour
   history (stored by ``_store_history``, with the history guard);
3. composition (``_finish_frame``): optional despike (isolated spikes the a-trous kept) ->
   remodulate, sum the signals, add emission, restore background -> optional TAA.

All buffers are float32 structure-of-arrays planes (the mode mask uint16), allocated once per
resolution and signal count and reused, so memory does not grow with the sequence length;
three exceptions are taken per frame and let go, so that nothing dead is held between
frames, where a file run holds the most (frames being read and written): the temporal
albedo's means (last frame's are dropped once this frame's are made), and a bidirectional
reverse pass's combination buffers and forward colour means (``forward_buffers``, released
once the output frame is composed).
Scratch is shared between stages (names are roles; a buffer is taken on first use): the
reprojected history is accumulated in place, the a-trous ping-pong reuses the demodulated
illumination once it is dead, last frame's history (dead once reprojected) lends its planes
as a-trous, guide and anti-lag scratch until it is replaced, the reprojection thresholds live
in the variance planes until the variance is estimated, and the output radiance is a fresh
array per frame handed to the caller (no resident copy). At 1080p the resident set including
the history is 344 MB with two signals and 473 MB with three.
"""

from __future__ import annotations

import dataclasses
import json
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TypeVar

import numpy as np

from svgf_cli.filters import modulate, values
from svgf_cli.filters.albedo_history import accumulate_albedo, combine_albedo
from svgf_cli.filters.antilag import antilag, cell_shape, scratch_shape
from svgf_cli.filters.atrous import atrous_iteration, luminance_stop_guides
from svgf_cli.filters.bidirectional import (
    CONSISTENCY_SIGMA,
    GLOSSY_REFERENCE_COUNT,
    PASS_ANTILAG_SIGMA_SCALE,
    STATIC_FILTERED_SHARE,
    STATIC_MOTION,
    SideHistory,
    combine_histories,
    consistent_lengths,
    effective_counts,
)
from svgf_cli.filters.clamp import firefly_clamp, history_clamp
from svgf_cli.filters.despike import despike, despike_lone
from svgf_cli.filters.edges import normal_squarings
from svgf_cli.filters.fastmath import float32_weights
from svgf_cli.filters.feedback import blend_history
from svgf_cli.filters.fireflies import spread_fireflies
from svgf_cli.filters.gradients import depth_gradients, normal_gradient, unit_normals
from svgf_cli.filters.params import (
    AUTO_ITERATIONS,
    AUTO_PIXEL_FILTER,
    SVGFParams,
    atrous_iterations_for,
)
from svgf_cli.filters.pixel_filter import pixel_filter, pixel_filter_weight
from svgf_cli.filters.reproject import accumulate_in_place, reproject
from svgf_cli.filters.taa import taa_resolve
from svgf_cli.filters.variance import estimate_variance
from svgf_cli.frame import DenoisedFrame, Frame, Signal

F32 = np.float32
Kept = TypeVar("Kept")

# Version of the state() layout: 2 = per-signal history length and modes, named signals.
STATE_FORMAT = 2

# A demodulation colour whose brightest channel exceeds this is not a reflectance (1 plus a
# tolerance for pixel-filter overshoot and half-float storage): such pixels are filtered as
# radiance.
MAX_REFLECTANCE = 1.05
# Per-channel demodulation floor relative to the pixel's brightest albedo channel (bounds
# the remodulation gain within a pixel's colour; see filters.modulate and
# bench/demodulation_floor.py).
RELATIVE_ALBEDO_FLOOR = 0.02

# Arrays that make up the persistent history; state() returns exactly these (plus metadata).
_HISTORY_SHAPES = {
    # name: (shape given (S, H, W), dtype)
    "history_illumination": (lambda s, h, w: (s, 3, h, w), F32),
    "history_moments": (lambda s, h, w: (s, 2, h, w), F32),
    "history_length": (lambda s, h, w: (s, h, w), F32),
    "history_mode": (lambda s, h, w: (h, w), np.uint16),
    "prev_depth": (lambda s, h, w: (h, w), F32),
    "prev_normal": (lambda s, h, w: (3, h, w), F32),
    "prev_mesh_id": (lambda s, h, w: (h, w), np.int32),
}

# Illumination-shaped (S, 3, H, W) scratch roles, in order of preference for a-trous outputs.
# "stale_colour" is last frame's colour history, dead once reprojected (see _lend_stale_history).
_ILLUMINATION_SCRATCH = (
    "demodulated", "accumulated", "stale_colour", "spare_a", "spare_b", "spare_c",
)


@dataclass
class _Workspace:
    """Per-frame scratch buffers for one resolution and signal count (reused every frame).

    A plane is allocated on first use, so optional stages (firefly clamp, colour blur, TAA)
    cost no memory unless enabled.
    """

    height: int
    width: int
    num_signals: int
    planes: dict[str, np.ndarray] = field(default_factory=dict)

    def shape(self, name: str) -> tuple[tuple[int, ...], type]:
        h, w, s = self.height, self.width, self.num_signals
        if name in _ILLUMINATION_SCRATCH or name.startswith("emitter_colour."):
            return ((s, 3, h, w) if name in _ILLUMINATION_SCRATCH else (3, h, w)), F32
        shapes: dict[str, tuple[tuple[int, ...], type]] = {
            "normal": ((3, h, w), F32),
            "ddx": ((h, w), F32),
            "ddy": ((h, w), F32),
            "mode": ((h, w), np.uint16),
            # resampled and then (in place) accumulated moments and history length
            "moments": ((s, 2, h, w), F32),
            "history_length": ((s, h, w), F32),
            "combined_moments": ((s, 2, h, w), F32),
            "combined_length": ((s, h, w), F32),
            "variance": ((s, h, w), F32),
            "variance_a": ((s, h, w), F32),
            "variance_b": ((s, h, w), F32),
            # the reprojection's normal threshold where "variance" has no second plane
            "normal_width": ((h, w), F32),
            "guide_luminance": ((s, h, w), F32),
            "guide_inverse_scale": ((s, h, w), F32),
            "taa": ((3, h, w), F32),
            # despike's luminance scratch, and firefly spreading's before it (the two never
            # overlap: one runs before the accumulation, the other after the a-trous)
            "despike_luminance": ((h, w), F32),
            "reflected_lights": ((h + 2, w + 2), np.uint8),
            "antilag_scratch": (scratch_shape(s, h, w), F32),
            "antilag_lambda": ((s, *cell_shape(h, w)), F32),
        }
        return shapes[name]

    def __getitem__(self, name: str) -> np.ndarray:
        plane = self.planes.get(name)
        if plane is None:
            shape, dtype = self.shape(name)
            plane = np.zeros(shape, dtype=dtype)
            self.planes[name] = plane
        return plane


@dataclass
class TemporalState:
    """What the Denoiser holds between reprojection and accumulation (the anti-lag hook).

    All arrays are the Denoiser's own buffers, (S, ...) with one entry per signal, in the
    order of ``names``. ``history_*`` are last frame's history resampled at this frame's
    pixels (``history_length`` 0 = no history); ``current`` is this frame's demodulated
    illumination (after the optional firefly clamp); ``mode`` is the (H, W) uint16 mask of
    its demodulation modes (bit s set: signal s is filtered as radiance at that pixel).
    A stage here may change the history in place; lowering ``history_length[s]`` at a
    pixel raises that signal's blend factor there, since accumulation uses
    ``alpha = max(alpha, 1 / (h + 1))`` per signal (h = 0: the current frame alone).
    """

    names: tuple[str, ...]
    current: np.ndarray
    mode: np.ndarray
    history_illumination: np.ndarray
    history_moments: np.ndarray
    history_length: np.ndarray
    depth: np.ndarray
    luminance_weights: tuple[np.float32, np.float32, np.float32]
    gradients: list[tuple[np.ndarray, np.ndarray, np.ndarray] | None] | None = None
    glossy: tuple[bool, ...] = ()
    # Where anti-lag may keep its statistics (None: a workspace plane of its own).
    antilag_scratch: np.ndarray | None = None
    # A pass of a bidirectional run: anti-lag tests at PASS_ANTILAG_SIGMA_SCALE of its sigma.
    bidirectional: bool = False


@dataclass
class _FrameRun:
    """One frame in flight through the phases: the frame, its workspace, the planes the
    temporal phase leaves for the later ones, the value-policy counts and the stage clock."""

    frame: Frame
    names: tuple[str, ...]
    work: _Workspace
    weights: tuple[np.float32, np.float32, np.float32]
    iterations: int  # a-trous iterations at this frame's size (atrous_iterations_for)
    bidirectional: bool = False  # a pass of a bidirectional run (forward_step, reverse_step)
    counts: dict[str, int] = field(
        default_factory=lambda: {"nonfinite": 0, "extreme": 0, "history_resets": 0})
    depth: np.ndarray = field(default_factory=lambda: np.empty((0, 0), F32))
    normal: np.ndarray = field(default_factory=lambda: np.empty((3, 0, 0), F32))
    motion: np.ndarray = field(default_factory=lambda: np.empty((2, 0, 0), F32))
    mode: np.ndarray = field(default_factory=lambda: np.empty((0, 0), np.uint16))
    illumination_name: str = "demodulated"  # the demodulated (+ clamped) frame
    # Scratch roles lent by last frame's history once it is reprojected (dead until
    # _store_history replaces it); they take precedence over the workspace's own planes.
    borrowed: dict[str, np.ndarray] = field(default_factory=dict)
    timings: dict[str, float] = field(default_factory=dict)
    cpu_timings: dict[str, float] = field(default_factory=dict)
    clock: tuple[float, float] = field(
        default_factory=lambda: (time.perf_counter(), time.process_time()))

    def plane(self, name: str) -> np.ndarray:
        """The scratch plane of role ``name``: borrowed from the stale history, else the
        workspace's own."""
        borrowed = self.borrowed.get(name)
        return borrowed if borrowed is not None else self.work[name]

    def lap(self, stage: str) -> None:
        """Add the wall and CPU time since the last lap to ``stage``."""
        now = (time.perf_counter(), time.process_time())
        self.timings[stage] = self.timings.get(stage, 0.0) + now[0] - self.clock[0]
        self.cpu_timings[stage] = self.cpu_timings.get(stage, 0.0) + now[1] - self.clock[1]
        self.clock = now


@dataclass
class _Filtered:
    """What the spatial phase leaves: the filtered illumination (and its workspace name),
    the name of the feedback iteration's output (the colour history), the variance
    entering the a-trous and the history length of the accumulation it filtered."""

    illumination: np.ndarray
    name: str
    history_name: str
    variance: np.ndarray
    history_length: np.ndarray


class Denoiser:
    """Spatiotemporal variance-guided filtering of a frame sequence (Schied et al. 2017).

    Feed frames in sequence order to :meth:`process`; the history persists between calls.
    A frame carries any number of named signals (``Frame.signals``); each is filtered on
    its own, with its own history (illumination, luminance moments, history length,
    demodulation mode per pixel) and variance, and the filtered signals are summed with the
    emission added back. The signal names must stay the same for the whole sequence.

    Per signal and pixel, a mode (``filters.modulate``): demodulated by the signal's colour
    where that is a plausible reflectance (brightest channel in ``[albedo_epsilon,
    MAX_REFLECTANCE]``, per-channel floor ``max(albedo_epsilon, RELATIVE_ALBEDO_FLOOR *
    brightest)``; for a signal with ``guide_albedo`` the floor ``albedo_epsilon`` is raised
    to ``guide_albedo_floor``), else filtered as radiance. Modes never exchange weight
    (a-trous, spatial variance) nor history (reprojection).

    Values (``filters.values``): non-finite and beyond-1e15 inputs are replaced and counted,
    demodulated values are clamped to +-1e15, the history can never hold a non-finite value.
    :attr:`DenoisedFrame.counts` reports all of it per frame (``frame.COUNT_KEYS``).

    **Anti-lag hook.** After reprojection and before accumulation, :meth:`process` builds a
    :class:`TemporalState` (per signal: the reprojected history illumination, moments and
    length, the current demodulated illumination and its mode) and calls
    :meth:`_before_accumulation` with it (history clamp, anti-lag), then firefly spreading
    (:meth:`_spread_fireflies`). Accumulation
    derives each signal's blend factor from that signal's own history length,
    ``alpha = max(alpha, 1/h)`` with ``h = min(cap, h_prev + 1)``, so an anti-lag stage only
    needs to lower ``history_length[s]`` per pixel (and may adjust the history itself).

    ``stage_seconds`` / ``stage_cpu_seconds`` hold the wall and process CPU time of each
    stage of the last frame (for benchmarks).
    """

    def __init__(self, params: SVGFParams, debug_layers: bool = False) -> None:
        _check_params(params)
        self.params = params
        self.debug_layers = debug_layers
        self._squarings = normal_squarings(params.sigma_normal)
        self._rules = {
            guide: (F32(max(params.albedo_epsilon, params.guide_albedo_floor if guide else 0.0)),
                    F32(MAX_REFLECTANCE), F32(RELATIVE_ALBEDO_FLOOR))
            for guide in (False, True)
        }
        # Effective sample counts per history length, for a bidirectional run's combination.
        self._colour_counts = effective_counts(params.alpha, params.history_cap)
        self._moment_counts = effective_counts(params.moments_alpha, params.history_cap)
        self._work: _Workspace | None = None
        self._signal_names: tuple[str, ...] | None = None
        self._history: dict[str, np.ndarray] | None = None
        # History arrays allocated before there is any history (the first frame lends them
        # as scratch; _store_history adopts them).
        self._fresh_history: dict[str, np.ndarray] | None = None
        self._taa_previous: np.ndarray | None = None
        # temporal_albedo: the running mean (U, 3, H, W) and length (U, H, W) of each
        # distinct demodulation colour (signals sharing one share a mean) and which colour
        # each signal has (``_albedo_slots``). Each frame's means go to fresh arrays and
        # last frame's are let go: no dead pair is held between frames.
        self._albedo: tuple[np.ndarray, np.ndarray] | None = None
        self._albedo_slots: tuple[int, ...] = ()
        # A bidirectional reverse pass: where the forward pass's colour means are put, from
        # forward_buffers to the end of the output frame.
        self._forward_albedo: tuple[np.ndarray, np.ndarray] | None = None
        self._frames_processed = 0
        self.stage_seconds: dict[str, float] = {}
        self.stage_cpu_seconds: dict[str, float] = {}

    # ----------------------------------------------------------------- public API
    @property
    def frames_processed(self) -> int:
        """Frames processed since construction or the last :meth:`reset`."""
        return self._frames_processed

    @property
    def signal_names(self) -> tuple[str, ...] | None:
        """The signals of the sequence so far (None before the first frame)."""
        return self._signal_names

    def held_bytes(self) -> int:
        """Bytes of the arrays this Denoiser keeps between frames (history, workspace,
        colour means, TAA), each counted once: its share of a run's memory."""
        arrays: list[np.ndarray] = []
        for group in (self._history, self._fresh_history,
                      self._work.planes if self._work is not None else None):
            arrays += list(group.values()) if group is not None else []
        for pair in (self._albedo, self._forward_albedo):
            arrays += list(pair) if pair is not None else []
        if self._taa_previous is not None:
            arrays.append(self._taa_previous)
        return sum({id(array): array.nbytes for array in arrays}.values())

    def reset(self) -> None:
        """Drop all history: the next frame is processed cold."""
        self._history = None
        self._taa_previous = None
        self._albedo = None
        self._albedo_slots = ()
        self._signal_names = None
        self._frames_processed = 0

    def process(self, frame: Frame) -> DenoisedFrame:
        """Denoise the next frame of the sequence.

        Three phases, each a method: :meth:`_accumulate_temporally` (values, geometry,
        demodulation, reprojection, the anti-lag hook, the blend),
        :meth:`_filter_spatially` (variance and the a-trous iterations; the output of the
        ``feedback_iteration`` is recorded as the colour history), then the history is
        stored and :meth:`_finish_frame` composes the output (remodulation, emission, TAA).
        """
        run = self._start_frame(frame)
        self._accumulate_temporally(run)
        self._accumulate_albedo(run)
        work = run.work
        filtered = self._filter_spatially(run, "accumulated", work["moments"],
                                          work["history_length"], run.iterations)
        # Hand this frame's buffers to the history by swapping (no copies); the workspace
        # takes the stale history arrays and overwrites them next frame.
        self._store_history(run, filtered.history_name)
        run.lap("history")
        return self._finish_frame(run, filtered)

    # ----------------------------------------------------------------- phases
    def _start_frame(self, frame: Frame) -> _FrameRun:
        """Check the frame against the sequence and open its workspace and stage clock."""
        frame.validate()
        frame = _writable(frame)
        names = frame.names
        if len(names) > modulate.MAX_SIGNALS:
            raise ValueError(f"at most {modulate.MAX_SIGNALS} signals, got {len(names)}")
        if self._signal_names is not None and self._signal_names != names:
            raise ValueError(
                f"signals changed from {'+'.join(self._signal_names)} to {'+'.join(names)}"
            )
        work = self._workspace(frame.height, frame.width, len(names))
        self._signal_names = names
        return _FrameRun(frame, names, work, float32_weights(frame.luminance_weights),
                         atrous_iterations_for(self.params, frame.height, frame.width))

    def _accumulate_temporally(
        self, run: _FrameRun, before_blend: Callable[[TemporalState], None] | None = None,
    ) -> None:
        """Phase 1, temporal accumulation: clean the geometry, gradients, demodulate every
        signal (+ firefly clamp), reproject every signal's history, the pre-accumulation
        hook (history clamp, anti-lag), blend. Leaves the accumulation in the workspace's
        ``accumulated``, ``moments`` and ``history_length``; ``run`` gets the planes the
        later phases read (depth, unit normals, motion, modes, the demodulated frame).
        ``before_blend`` (a bidirectional run's passes) sees the resampled history after
        the hook, also on a frame without history (length 0), and must not change it."""
        p = self.params
        work, counts, frame = run.work, run.counts, run.frame
        depth, normal_in, motion = self._clean_geometry(frame, counts)
        run.lap("values")

        normal = work["normal"]
        unit_normals(normal_in, depth, normal)
        # The reprojection thresholds are only needed until the variance is estimated: they
        # borrow its planes (a plane of their own for the second with one signal).
        depth_slope = work["variance"][0]
        normal_width = work["variance"][1] if run.work.num_signals > 1 else work["normal_width"]
        depth_gradients(depth, work["ddx"], work["ddy"], depth_slope)
        normal_gradient(normal, depth, normal_width)
        run.lap("gradients")

        illumination_name = "demodulated"
        illumination = work[illumination_name]
        mode = work["mode"]
        marked: dict[str, int] = {}
        if p.glossy_emitter_radiance:
            frame = run.frame = self._mark_reflected_lights(frame, depth, work, marked)
        self._demodulate(frame.signals, depth, illumination, mode, counts)
        for name, total in marked.items():
            # Their colour (the G-buffer albedo) is above 1 by construction: information,
            # not an implausible colour pass.
            counts[f"reflected_light.{name}"] = total
            counts[f"implausible_albedo.{name}"] -= total
        if p.firefly_clamp > 0.0:
            firefly_clamp(illumination, depth, F32(p.firefly_clamp), run.weights,
                          work["spare_a"])
            illumination_name = "spare_a"
            illumination = work[illumination_name]
        run.depth, run.normal, run.motion, run.mode = depth, normal, motion, mode
        run.illumination_name = illumination_name
        run.lap("demodulate")

        # Reproject into the accumulation buffers and accumulate in place (element-wise).
        accumulated = work["accumulated"]
        moments = work["moments"]
        history_length = work["history_length"]
        history = self._history
        if p.temporal and history is not None:
            reproject(
                motion, depth, normal, frame.mesh_id, mode, depth_slope, normal_width,
                history["prev_depth"], history["prev_normal"], history["prev_mesh_id"],
                history["history_mode"], history["history_illumination"],
                history["history_moments"], history["history_length"], F32(p.depth_tolerance),
                F32(p.depth_slack), F32(p.normal_tolerance), accumulated, moments,
                history_length, catmull_rom=p.history_catmull_rom,
            )
            self._lend_stale_history(run)
            temporal = TemporalState(
                run.names, illumination, mode, accumulated, moments, history_length, depth,
                run.weights, _gradient_samples(frame) if p.antilag_gradients else None,
                tuple(signal.glossy for signal in frame.signals),
                antilag_scratch=run.plane("antilag_scratch"), bidirectional=run.bidirectional,
            )
            shortened = self._before_accumulation(temporal)
            if p.antilag:
                counts["antilag"] = shortened
            if p.spread_fireflies > 0.0:
                counts.update(self._spread_fireflies(temporal, frame.signals))
        else:
            # Blend factor 1 everywhere; clear the stale contents (weight 0, but 0 * inf).
            history_length.fill(0.0)
            accumulated.fill(0.0)
            moments.fill(0.0)
            self._lend_stale_history(run)
            temporal = TemporalState(run.names, illumination, mode, accumulated, moments,
                                     history_length, depth, run.weights,
                                     bidirectional=run.bidirectional)
        if before_blend is not None:
            before_blend(temporal)
        accumulate_in_place(
            illumination, accumulated, moments, history_length, depth, F32(p.alpha),
            F32(p.moments_alpha), F32(p.history_cap), run.weights,
        )
        run.lap("reproject")

    def _filter_spatially(
        self, run: _FrameRun, source: str, moments: np.ndarray, history_length: np.ndarray,
        iterations: int, protected: tuple[str, ...] = (), feeds_back: bool = True,
    ) -> _Filtered:
        """Phase 2, spatial filtering of the accumulation in the workspace buffer ``source``
        (with its ``moments`` and ``history_length``): the variance (+ the optional colour
        blur), then a-trous iterations 0 .. ``iterations - 1``. The output of the feedback
        iteration (``feedback_iteration``, clamped to the configured iterations; -1: the
        colour entering the a-trous) is recorded as the colour history and never
        overwritten, nor are the buffers named in ``protected``. The demodulated frame is
        scratch here (dead once accumulated). Without ``feeds_back`` (a bidirectional run's
        combined accumulation, which is no pass's history) nothing is kept, which saves a
        buffer."""
        p = self.params
        work, mode, depth, normal, weights = run.work, run.mode, run.depth, run.normal, run.weights
        busy = (source, *protected)

        def scratch(*taken: str) -> str:
            """An illumination-shaped buffer name not taken."""
            for name in _ILLUMINATION_SCRATCH:
                if name not in taken and name not in protected:
                    return name
            raise AssertionError("out of scratch buffers")

        variance = work["variance"]
        filtered_name = source
        blurred = None
        if p.spatial_variance_blur_color:
            filtered_name = scratch(*busy)
            blurred = run.plane(filtered_name)
        estimate_variance(
            run.plane(source), moments, history_length, mode, depth, work["ddx"], work["ddy"],
            normal, history_threshold=float(p.variance_history_threshold),
            radius=p.spatial_variance_radius, sigma_depth=p.sigma_depth,
            sigma_luminance=p.spatial_variance_sigma_luminance, squarings=self._squarings,
            sigma_normal=p.sigma_normal, out_variance=variance, out_illumination=blurred,
        )
        run.lap("variance")

        # The colour history: the unfiltered accumulation unless an iteration feeds back.
        # That iteration's output is protected so later iterations cannot overwrite it.
        # The last iteration's propagated variance is never read, so it is not computed.
        feedback = min(p.feedback_iteration, run.iterations - 1) if feeds_back else -1
        # Where pixels move the history keeps only a share of the feedback output: the blend
        # goes into the colour entering the a-trous, kept until that iteration has run.
        keep_unfiltered = feedback >= 0 and p.moving_feedback_share < 1.0
        unfiltered_name = filtered_name
        history_name = filtered_name
        filtered_name_now = filtered_name
        filtered = run.plane(filtered_name)
        filtered_variance = variance
        # "variance" itself is reported as a debug layer; otherwise it is scratch after use.
        variance_names = ("variance_a", "variance_b")
        if not self.debug_layers:
            variance_names = ("variance_a", "variance", "variance_b")
        guide_luminance = run.plane("guide_luminance")
        guide_inverse_scale = run.plane("guide_inverse_scale")
        groups = signal_groups(len(run.names))
        sigmas = [signal_sigma_luminance(p, signal) for signal in run.frame.signals]
        for iteration in range(iterations):
            out_name = scratch(filtered_name_now, history_name if feeds_back else "",
                               unfiltered_name if keep_unfiltered else "")
            if iteration == feedback and not keep_unfiltered:
                history_name = out_name
            propagate = iteration + 1 < iterations
            out_variance = filtered_variance  # not written when not propagated
            if propagate:
                out_variance = next(
                    run.plane(v) for v in variance_names
                    if run.plane(v) is not filtered_variance
                )
            out_illumination = run.plane(out_name)
            # Signals in groups of two or three: the kernel is register-blocked for them,
            # sharing the geometric weights (each signal keeps its own sigma_l).
            for group in groups:
                luminance_stop_guides(
                    filtered[group], filtered_variance[group], mode, group.start, depth,
                    sigmas[group], weights, guide_luminance[group],
                    guide_inverse_scale[group],
                )
                atrous_iteration(
                    filtered[group], filtered_variance[group], guide_luminance[group],
                    guide_inverse_scale[group], depth, work["ddx"], work["ddy"], normal,
                    1 << iteration, p.sigma_depth, p.sigma_normal, propagate,
                    out_illumination[group], out_variance[group],
                )
            if iteration == feedback and keep_unfiltered:
                blend_history(run.plane(unfiltered_name), out_illumination, run.motion,
                              F32(STATIC_MOTION), F32(1.0), F32(p.moving_feedback_share))
                history_name, keep_unfiltered = unfiltered_name, False
            filtered, filtered_variance = out_illumination, out_variance
            filtered_name_now = out_name
        run.lap("atrous")
        return _Filtered(filtered, filtered_name_now, history_name, variance, history_length)

    def _finish_frame(self, run: _FrameRun, filtered: _Filtered) -> DenoisedFrame:
        """Phase 3, composition: remodulate, sum the signals, add the emission, restore the
        background (+ TAA); record the frame's stage times."""
        p = self.params
        illumination = filtered.illumination
        if p.despike > 0.0:
            illumination = self._despike(run, filtered)
            run.lap("despike")
        output, layers = self._compose(run.frame, illumination, filtered.variance,
                                       filtered.history_length, run.mode, run.depth,
                                       run.counts)
        run.lap("modulate")
        if p.despike > 0.0:
            self._despike_lone(run, output)
            run.lap("despike")

        if p.taa:
            if self._taa_previous is None:
                self._taa_previous = output.copy()
            else:
                taa_resolve(output, self._taa_previous, run.motion, run.depth,
                            np.array(run.weights, dtype=F32), F32(p.taa_alpha),
                            run.work["taa"])
                np.copyto(self._taa_previous, run.work["taa"])
            output = self._taa_previous.copy()
            run.lap("taa")
        weight = pixel_filter_weight(p.pixel_filter, run.frame.centre_sampled)
        if weight > 0.0:
            # After TAA, whose history must stay the unfiltered output (the kernel would
            # compound over the frames).
            emission = run.frame.emission
            if emission is None:
                emission = np.zeros_like(output)
            filtered_output = np.empty_like(output)
            pixel_filter(output, emission, F32(weight), filtered_output)
            output = filtered_output
            run.lap("pixel_filter")

        self._frames_processed += 1
        self.stage_seconds = run.timings
        self.stage_cpu_seconds = run.cpu_timings
        return DenoisedFrame(color=output, layers=layers, counts=run.counts)

    def _despike(self, run: _FrameRun, filtered: _Filtered) -> np.ndarray:
        """The despiked output illumination (``filters.despike``), counted per signal. In
        place unless the output is the colour history (no a-trous iteration after the
        feedback one): the history keeps the samples."""
        illumination = filtered.illumination
        if filtered.name == filtered.history_name:
            illumination = illumination.copy()
        clamped = np.zeros((run.depth.shape[0], len(run.names)), dtype=np.int64)
        despike(illumination, run.mode, run.depth, F32(self.params.despike), run.weights,
                run.work["despike_luminance"], clamped)
        for name, total in zip(run.names, clamped.sum(axis=0), strict=True):
            run.counts[f"despiked.{name}"] = int(total)
        return illumination

    def _despike_lone(self, run: _FrameRun, output: np.ndarray) -> None:
        """The composed output's pixels whose mode no neighbour shares, despiked against
        their output neighbours (``filters.despike.despike_lone``), counted."""
        emission = run.frame.emission
        clamped = np.zeros(run.depth.shape[0], dtype=np.int64)
        despike_lone(output, emission if emission is not None else output,
                     emission is not None, run.mode, run.depth, len(run.names),
                     F32(self.params.despike), run.weights, run.work["despike_luminance"],
                     clamped)
        run.counts["despiked_lone"] = int(clamped.sum())

    # ----------------------------------------------------------------- bidirectional
    def forward_step(self, frame: Frame,
                     keep: Callable[[SideHistory], Kept] | None = None) -> Kept | SideHistory:
        """The forward pass of a bidirectional run (``filters.two_pass``): the next frame's
        temporal accumulation, its unfiltered accumulation stored as the history
        (:meth:`_pass_history`: the pass continues bit-identically to a causal run with
        ``feedback_iteration`` -1), no output.
        Returns ``keep`` applied to the history it resampled (after anti-lag, before the
        blend; views of this Denoiser's buffers, valid only during the call), by default a
        copy."""
        run = self._start_frame(frame)
        run.bidirectional = True
        kept: list[Kept | SideHistory] = []

        def capture(temporal: TemporalState) -> None:
            albedo = albedo_length = None
            if self.params.temporal_albedo:
                self._accumulate_albedo(run)
                albedo, albedo_length = self._albedo or (None, None)
            side = SideHistory(temporal.history_illumination, temporal.history_moments,
                               temporal.history_length, albedo, albedo_length)
            kept.append(keep(side) if keep is not None else SideHistory(
                side.colour.copy(), side.moments.copy(), side.length.copy(),
                None if albedo is None else albedo.copy(),
                None if albedo_length is None else albedo_length.copy()))

        self._accumulate_temporally(run, capture)
        self._store_history(run, self._pass_history(run))
        self._frames_processed += 1
        return kept[0]

    def forward_buffers(self, num_signals: int, height: int, width: int) -> SideHistory:
        """The buffers :meth:`reverse_step` combines in. A forward history written into them
        (a file run unpacks the spilled state there) is combined in place; any other is
        copied in first. They do not outlive the next :meth:`reverse_step` that outputs a
        frame (it lets them go: :meth:`_release_forward_buffers`)."""
        work = self._workspace(height, width, num_signals)
        albedo = albedo_length = None
        if self.params.temporal_albedo:
            # One per distinct colour, as this pass has them (all signals' before its first
            # frame); a forward history of another count is copied into fresh buffers.
            albedo, albedo_length = self._forward_albedo_buffers(
                _colour_count(self._albedo_slots) or num_signals, height, width)
        return SideHistory(work[self._combined_name()], work["combined_moments"],
                           work["combined_length"], albedo, albedo_length)

    def _combined_name(self) -> str:
        # A spare buffer that is neither the pass's own accumulation nor the demodulated
        # frame (which the firefly clamp puts in spare_a).
        return "spare_b" if self.params.firefly_clamp > 0.0 else "spare_a"

    def reverse_step(self, frame: Frame, forward: SideHistory | None) -> DenoisedFrame | None:
        """The reverse pass of a bidirectional run: ``frame.motion`` points to the frame
        processed before (the next one in time). Temporal accumulation of its own history,
        as :meth:`forward_step`; with ``forward`` (the forward pass's :meth:`forward_step`
        history at the same frame, best given in :meth:`forward_buffers`) also the
        consistency test between both histories and their combination with this frame
        (``filters.bidirectional``), filtered spatially and composed into the output.
        None without ``forward`` (a warm-up frame of the reverse pass)."""
        if self.params.taa:
            raise ValueError("TAA filters the output causally; it cannot run bidirectionally")
        run = self._start_frame(frame)
        run.bidirectional = True
        work = run.work
        combined = self._combined_name()
        combine = None
        if forward is not None:
            into = self.forward_buffers(len(run.names), frame.height, frame.width)
            pairs = [(forward.colour, into.colour), (forward.moments, into.moments),
                     (forward.length, into.length)]
            if forward.albedo is not None and forward.albedo_length is not None:
                into.albedo, into.albedo_length = self._forward_albedo_buffers(
                    *forward.albedo_length.shape)
                pairs += [(forward.albedo, into.albedo),
                          (forward.albedo_length, into.albedo_length)]
            for given, buffer in pairs:
                if given is not buffer:
                    if given.shape != buffer.shape:
                        raise ValueError(f"forward history of shape {given.shape}, expected "
                                         f"{buffer.shape}")
                    np.copyto(buffer, given)

            # n_ref per signal: a long causal history's count, GLOSSY_REFERENCE_COUNT for
            # glossy signals (filters.bidirectional).
            reference_counts = np.array(
                [GLOSSY_REFERENCE_COUNT if signal.glossy else self._moment_counts[-1]
                 for signal in frame.signals], dtype=F32)

            def combine(temporal: TemporalState) -> None:
                # The reverse pass blends with its own length, so its shortened one goes to
                # scratch (the variance planes are dead until the variance is estimated).
                reverse_length = work["variance_b"]
                consistent_lengths(
                    temporal.current, into.moments, into.length, temporal.history_moments,
                    temporal.history_length, temporal.depth, self._colour_counts,
                    run.weights, F32(CONSISTENCY_SIGMA), into.length, reverse_length,
                )
                combine_histories(
                    temporal.current, temporal.history_illumination, temporal.history_moments,
                    reverse_length, temporal.depth, self._colour_counts,
                    self._moment_counts, run.weights, reference_counts,
                    into.colour, into.moments, into.length,
                )

        self._accumulate_temporally(run, combine)
        self._accumulate_albedo(run)
        if forward is not None and forward.albedo is not None:
            self._combine_albedo(run, into)
        own_history = self._pass_history(run, protected=(combined,) if forward else ())
        filtered = None
        if forward is not None:
            filtered = self._filter_spatially(
                run, combined, work["combined_moments"], work["combined_length"],
                run.iterations, protected=(own_history,), feeds_back=False,
            )
        self._store_history(run, own_history)
        run.lap("history")
        if filtered is None:
            self._frames_processed += 1
            return None
        output = self._finish_frame(run, filtered)
        self._release_forward_buffers(work)
        return output

    def _release_forward_buffers(self, work: _Workspace) -> None:
        """Let the combination buffers (:meth:`forward_buffers`) go once the output frame is
        composed: dead until the next output frame's forward state is unpacked, they are
        not held between frames, where a file run holds the most (the frame being written,
        the one being read and the next packed state). Allocated again by the next
        :meth:`forward_buffers`: a mapping of its own each (``svgf_cli.heap``)."""
        for name in (self._combined_name(), "combined_moments", "combined_length"):
            work.planes.pop(name, None)
        self._forward_albedo = None

    def _pass_history(self, run: _FrameRun, protected: tuple[str, ...] = ()) -> str:
        """The colour history a pass of a bidirectional run keeps (the workspace buffer's
        name): its accumulation as blended (with the variance stage's colour blur,
        ``spatial_variance_blur_color``, the colour entering the a-trous), and where the
        pixel does not move a share ``STATIC_FILTERED_SHARE`` of the first a-trous
        iteration's output (``filters.feedback.blend_history``; a causal run keeps all of its
        feedback iteration's output there, and ``moving_feedback_share`` of it where the
        pixel moves). The combination weighs each side as
        an average of its effective samples; a spatially filtered history is a blurred one,
        and where the pixels move the blur compounds with the resampling in both passes;
        where they do not, some of it pays (``docs/bidirectional.md``)."""
        work = run.work
        filtered = self._filter_spatially(run, "accumulated", work["moments"],
                                          work["history_length"], min(1, run.iterations),
                                          protected, feeds_back=False)
        if filtered.name == filtered.history_name:
            return filtered.name  # no a-trous iteration: the accumulation itself
        blend_history(run.plane(filtered.history_name), run.plane(filtered.name), run.motion,
                      F32(STATIC_MOTION), F32(STATIC_FILTERED_SHARE), F32(0.0))
        return filtered.history_name

    def state(self) -> dict[str, np.ndarray]:
        """Everything needed to continue the sequence bit-identically (copies)."""
        state: dict[str, np.ndarray] = {
            "format_version": np.array(STATE_FORMAT, dtype=np.int64),
            "params": _encode(self.params.to_json()),
            "frames_processed": np.array(self._frames_processed, dtype=np.int64),
        }
        if self._signal_names is not None:
            state["signals"] = _encode(",".join(self._signal_names))
        if self._history is not None:
            for key in _HISTORY_SHAPES:
                state[key] = self._history[key].copy()
        if self._taa_previous is not None:
            state["taa_previous"] = self._taa_previous.copy()
        if self._albedo is not None:
            state["albedo_history"] = self._albedo[0].copy()
            state["albedo_length"] = self._albedo[1].copy()
            state["albedo_slots"] = np.array(self._albedo_slots, dtype=np.int64)
        return state

    def load_state(self, state: dict[str, np.ndarray]) -> None:
        """Continue from :meth:`state`; ValueError if it was saved by another state format,
        with other parameters or with inconsistent shapes."""
        try:
            version = int(np.asarray(state["format_version"])) if "format_version" in state else 1
            saved_params = _decode(state["params"])
            frames = int(np.asarray(state["frames_processed"]))
        except (KeyError, TypeError, ValueError, UnicodeDecodeError) as exc:
            raise ValueError(f"not a denoiser state: {exc}") from exc
        if version != STATE_FORMAT:
            raise ValueError(
                f"denoiser state has format {version}, this version reads format "
                f"{STATE_FORMAT} (per-signal history); rebuild the history with a warm-up"
            )
        if json.loads(saved_params) != json.loads(self.params.to_json()):
            raise ValueError("denoiser state was saved with different parameters")
        names = tuple(_decode(state["signals"]).split(",")) if "signals" in state else None
        history: dict[str, np.ndarray] | None = None
        if "history_illumination" in state:
            if names is None:
                raise ValueError("denoiser state has history but no signal names")
            missing = [k for k in _HISTORY_SHAPES if k not in state]
            if missing:
                raise ValueError(f"denoiser state lacks {', '.join(missing)}")
            height, width = np.asarray(state["prev_depth"]).shape
            history = {}
            for key, (shape_of, dtype) in _HISTORY_SHAPES.items():
                array = np.asarray(state[key])
                shape = shape_of(len(names), height, width)
                if array.shape != shape:
                    raise ValueError(
                        f"denoiser state {key}: shape {array.shape}, expected {shape} for "
                        f"signals {'+'.join(names)}"
                    )
                history[key] = np.array(array, dtype=dtype, copy=True, order="C")
            # A state file is input too: it must obey the value policy.
            values.reset_nonfinite_history(
                history["history_illumination"], history["history_moments"],
                history["history_length"], history["history_mode"],
            )
        taa_previous = None
        if "taa_previous" in state:
            taa_previous = np.array(state["taa_previous"], dtype=F32, copy=True, order="C")
            if history is not None and taa_previous.shape[1:] != history["prev_depth"].shape:
                raise ValueError("denoiser state taa_previous does not match the history shape")
        albedo, slots = _albedo_state(state, history)
        self._history = history
        self._taa_previous = taa_previous
        self._albedo, self._albedo_slots = albedo, slots
        self._signal_names = names
        self._frames_processed = frames

    # ----------------------------------------------------------------- stages
    def _clean_geometry(
        self, frame: Frame, counts: dict[str, int]
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Depth, normal and motion obeying the value policy: the frame's own planes when
        they are clean (the common case: a read-only scan), cleaned copies otherwise."""
        cleaners = (("depth", frame.depth, values.cleaned_depth),
                    ("normal", frame.normal, values.cleaned_normal),
                    ("motion", frame.motion, values.cleaned_motion))
        found = values.count_geometry(frame.depth, frame.normal, frame.motion)
        planes = []
        for name, plane, cleaned in cleaners:
            nonfinite, extreme = found[name]
            if name == "motion":
                extreme = 0  # far-away motion only means "no history": nothing overflows
            _add(counts, "nonfinite", name, nonfinite)
            _add(counts, "extreme", name, extreme)
            planes.append(cleaned(plane) if nonfinite or extreme else plane)
        return planes[0], planes[1], planes[2]

    def _demodulate(self, signals: list[Signal], depth: np.ndarray, out: np.ndarray,
                    mode: np.ndarray, counts: dict[str, int]) -> None:
        rows = np.zeros((depth.shape[0], modulate.DEMODULATE_COUNTERS), dtype=np.int64)
        for index, signal in enumerate(signals):
            modulate.demodulate(signal.radiance, signal.albedo, depth,
                                *self._rules[signal.guide_albedo],
                                index, out[index], mode, rows)
            total = rows.sum(axis=0)
            name = signal.name
            _add(counts, "nonfinite", f"radiance.{name}", int(total[modulate.NONFINITE_RADIANCE]))
            _add(counts, "extreme", f"radiance.{name}", int(total[modulate.EXTREME_RADIANCE]))
            _add(counts, "nonfinite", f"albedo.{name}", int(total[modulate.NONFINITE_ALBEDO]))
            counts[f"clamped.{name}"] = int(total[modulate.CLAMPED])
            counts[f"radiance_mode.{name}"] = int(total[modulate.RADIANCE_MODE])
            counts[f"implausible_albedo.{name}"] = int(total[modulate.IMPLAUSIBLE])

    def _mark_reflected_lights(self, frame: Frame, depth: np.ndarray, work: _Workspace,
                               marked: dict[str, int]) -> Frame:
        """The frame with each glossy signal's demodulation colour replaced by the G-buffer
        albedo where that is no reflectance (``modulate.emitter_colour``): a specular path
        reached a light there, and the signal is filtered as radiance. Written into
        workspace planes (the caller's planes are never modified); demodulation and
        remodulation both read the replaced colour, so the modes agree. ``marked`` gets the
        surface pixels marked per glossy signal."""
        marked.update({signal.name: 0 for signal in frame.signals if signal.glossy})
        if not marked:
            return frame
        lit = work["reflected_lights"]
        if not modulate.reflected_lights(frame.albedo, F32(MAX_REFLECTANCE), lit):
            return frame  # the albedo AOV is a reflectance everywhere: nothing to mark
        rows = np.zeros(frame.height, dtype=np.int64)
        signals = []
        for index, signal in enumerate(frame.signals):
            if signal.glossy:
                colour = work[f"emitter_colour.{index}"]
                modulate.emitter_colour(signal.albedo, frame.albedo, lit, depth, colour, rows)
                marked[signal.name] = int(rows.sum())
                signal = dataclasses.replace(signal, albedo=colour)
            signals.append(signal)
        return dataclasses.replace(frame, signals=signals)

    def _before_accumulation(self, temporal: TemporalState) -> int:
        """Adjust the reprojected history before it is blended: the optional history clamp,
        then anti-lag. Returns how many (signal, pixel) histories anti-lag shortened."""
        p = self.params
        glossy_k = p.glossy_history_clamp or p.history_clamp
        ks = [glossy_k if glossy else p.history_clamp
              for glossy in temporal.glossy or (False,) * len(temporal.names)]
        if max(ks) > 0.0:  # one pass for all signals; k <= 0 leaves a signal alone
            history_clamp(temporal.history_illumination, temporal.history_moments,
                          temporal.history_length, temporal.current, temporal.depth, ks,
                          temporal.luminance_weights)
        if not p.antilag:
            return 0
        work = self._work
        assert work is not None
        scratch = temporal.antilag_scratch
        if scratch is None:
            scratch = work["antilag_scratch"]
        # A bidirectional pass's false alarm costs less: the other side refills the history.
        sigma = p.antilag_sigma * (PASS_ANTILAG_SIGMA_SCALE if temporal.bidirectional else 1.0)
        return antilag(
            temporal.current, temporal.history_moments, temporal.history_length,
            temporal.depth, np.array(temporal.luminance_weights, dtype=F32), p.antilag_radius,
            sigma, p.antilag_spatial_samples, p.antilag_tolerance, p.moments_alpha,
            scratch, work["antilag_lambda"], temporal.gradients,
        )

    def _accumulate_albedo(self, run: _FrameRun) -> None:
        """With ``temporal_albedo``: each signal's demodulation colour becomes its running
        mean over frames (``filters.albedo_history``), kept as history, one per distinct
        colour (:func:`_colour_slots`); ``run.frame``'s signals take it, so the composition
        remodulates by it. Runs after the temporal phase (demodulation used this frame's
        colour) and before the history is stored (last frame's depth and mesh id)."""
        p = self.params
        if not p.temporal_albedo:
            return
        frame = run.frame
        slots, sources = _colour_slots(frame.signals)
        if not sources:
            return  # only glossy signals: no colour to average
        count, h, w = len(sources), frame.height, frame.width
        shape = (count, 3, h, w)
        history, previous = self._albedo, self._history
        if (history is None or slots != self._albedo_slots or previous is None
                or not p.temporal):
            # No history: a length-0 plane rejects every tap.
            history = (np.zeros(shape, dtype=F32), np.zeros((count, h, w), dtype=F32))
            prev_depth, prev_mesh_id = run.depth, frame.mesh_id
        else:
            prev_depth, prev_mesh_id = previous["prev_depth"], previous["prev_mesh_id"]
        # Fresh (a mapping of its own, given back when freed: svgf_cli.heap), so that last
        # frame's pair is not kept alive as the next frame's spare.
        colour, length = np.empty(shape, dtype=F32), np.empty((count, h, w), dtype=F32)
        for slot, source in enumerate(sources):
            signal = frame.signals[source]
            accumulate_albedo(
                signal.albedo, history[0][slot], history[1][slot], run.motion, run.depth,
                frame.mesh_id, prev_depth, prev_mesh_id, F32(p.alpha), F32(p.history_cap),
                *self._rules[signal.guide_albedo], colour[slot], length[slot],
                catmull_rom=p.albedo_catmull_rom,
            )
        self._albedo, self._albedo_slots = (colour, length), slots
        signals = [signal if slot < 0 else dataclasses.replace(signal, albedo=colour[slot])
                   for signal, slot in zip(frame.signals, slots, strict=True)]
        run.frame = dataclasses.replace(frame, signals=signals)
        run.lap("albedo")

    def _forward_albedo_buffers(self, count: int, height: int,
                                width: int) -> tuple[np.ndarray, np.ndarray]:
        """Where a bidirectional reverse pass puts the forward pass's ``count`` colour
        means (kept from frame to frame)."""
        shape = (count, 3, height, width)
        if self._forward_albedo is None or self._forward_albedo[0].shape != shape:
            self._forward_albedo = (np.zeros(shape, dtype=F32),
                                    np.zeros((count, height, width), dtype=F32))
        return self._forward_albedo

    def _combine_albedo(self, run: _FrameRun, forward: SideHistory) -> None:
        """A bidirectional output frame: remodulate by both passes' colour means weighted by
        their effective sample counts (``albedo_history.combine_albedo``), written over the
        forward pass's (``forward_buffers``: dead after this frame). A forward history with
        another set of colours (it cannot happen with one reader) is not combined."""
        assert self._albedo is not None
        assert forward.albedo is not None and forward.albedo_length is not None
        reverse, reverse_length = self._albedo
        if forward.albedo.shape != reverse.shape:
            return
        frame = run.frame
        # The signals already hold views of the reverse means: the slots are the pass's.
        slots = self._albedo_slots
        for slot in range(reverse.shape[0]):
            signal = frame.signals[slots.index(slot)]
            combine_albedo(
                forward.albedo[slot], forward.albedo_length[slot], reverse[slot],
                reverse_length[slot], signal.albedo, self._colour_counts,
                *self._rules[signal.guide_albedo], forward.albedo[slot],
            )
        signals = [signal if slot < 0 else dataclasses.replace(signal, albedo=forward.albedo[slot])
                   for signal, slot in zip(frame.signals, slots, strict=True)]
        run.frame = dataclasses.replace(frame, signals=signals)

    def _spread_fireflies(self, temporal: TemporalState,
                          signals: list[Signal]) -> dict[str, int]:
        """Bound the current samples that are fireflies against the history anti-lag left
        and share their excess over their surface (``filters.fireflies``); glossy signals
        are left alone. Not on a frame without history: a single frame cannot tell a small
        highlight in a combined colour from a firefly. Returns the count per signal."""
        work = self._work
        assert work is not None
        glossy = temporal.glossy or (False,) * len(temporal.names)
        spread = spread_fireflies(
            temporal.current, [signal.albedo for signal in signals],
            tuple(signal.guide_albedo for signal in signals), temporal.history_moments,
            temporal.mode, temporal.depth,
            tuple(not g for g in glossy), self.params.spread_fireflies,
            temporal.luminance_weights, work["despike_luminance"])
        return {f"fireflies_spread.{name}": count
                for name, count in zip(temporal.names, spread, strict=True)}

    def _compose(
        self, frame: Frame, filtered: np.ndarray, variance: np.ndarray,
        history_length: np.ndarray, mode: np.ndarray, depth: np.ndarray,
        counts: dict[str, int],
    ) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        """Remodulate, restore the background, sum the signals and add the emission straight
        into a fresh output array (handed to the caller, so nothing full-frame stays
        resident); the debug layers when asked."""
        height, width = depth.shape
        radiance = np.zeros((3, height, width), dtype=F32)
        emission = frame.emission
        has_emission = emission is not None
        # Without emission any (3, H, W) float32 plane will do: the kernel never reads it.
        emission_plane = emission if emission is not None else radiance
        rows = np.zeros((height, 2), dtype=np.int64)
        layers: dict[str, np.ndarray] = {}
        for index, signal in enumerate(frame.signals):
            add_emission = has_emission and index == 0
            modulate.remodulate_add(filtered[index], signal.radiance, signal.albedo, depth,
                                    emission_plane, add_emission,
                                    *self._rules[signal.guide_albedo], radiance, rows)
            if add_emission:
                total = rows.sum(axis=0)
                _add(counts, "nonfinite", "emission", int(total[0]))
                _add(counts, "extreme", "emission", int(total[1]))
            if self.debug_layers:
                name = signal.name
                alone = np.zeros((3, height, width), dtype=F32)
                modulate.remodulate_add(filtered[index], signal.radiance, signal.albedo, depth,
                                        emission_plane, False,
                                        *self._rules[signal.guide_albedo], alone, rows)
                for c, channel in enumerate("RGB"):
                    layers[f"{name}.{channel}"] = alone[c]
                layers[f"variance.{name}"] = variance[index].copy()
                layers[f"history_length.{name}"] = history_length[index].copy()
                layers[f"radiance_mode.{name}"] = ((mode >> index) & 1).astype(F32)
                if self.params.antilag and self._work is not None:
                    layers[f"antilag.{name}"] = _cells_to_pixels(
                        self._work["antilag_lambda"][index], height, width)
        return radiance, layers

    # ----------------------------------------------------------------- internals
    def _resolution(self) -> tuple[int, int] | None:
        if self._history is not None:
            h, w = self._history["prev_depth"].shape
            return int(w), int(h)
        if self._taa_previous is not None:
            return int(self._taa_previous.shape[2]), int(self._taa_previous.shape[1])
        return None

    def _workspace(self, height: int, width: int, num_signals: int) -> _Workspace:
        previous = self._resolution()
        if previous is not None and previous != (width, height):
            raise ValueError(
                f"resolution changed from {previous[0]}x{previous[1]} to {width}x{height}"
            )
        work = self._work
        if work is None or (work.height, work.width, work.num_signals) != (
            height, width, num_signals
        ):
            work = _Workspace(height, width, num_signals)
            self._work = work
        return work

    def _history_buffers(self, work: _Workspace) -> dict[str, np.ndarray]:
        """The history arrays: last frame's history, or before there is one a fresh set that
        :meth:`_store_history` adopts (so the first frame's scratch is no extra memory)."""
        shape = _HISTORY_SHAPES["history_illumination"][0](work.num_signals, work.height,
                                                           work.width)
        history = self._history
        if history is not None and history["history_illumination"].shape == shape:
            return history
        fresh = self._fresh_history
        if fresh is None or fresh["history_illumination"].shape != shape:
            h, w, s = work.height, work.width, work.num_signals
            fresh = {key: np.zeros(shape_of(s, h, w), dtype=dtype)
                     for key, (shape_of, dtype) in _HISTORY_SHAPES.items()}
            self._fresh_history = fresh
        return fresh

    def _lend_stale_history(self, run: _FrameRun) -> None:
        """Once reprojected, last frame's colour, moments and length are dead until
        :meth:`_store_history` replaces them: they lend their memory to this frame as
        scratch (an a-trous colour buffer, the guides, a variance buffer, the anti-lag
        scratch), 3S + S + 2S planes the workspace no longer needs."""
        work = run.work
        stale = self._history_buffers(work)
        s, h, w = work.num_signals, work.height, work.width
        colour = stale["history_illumination"]
        # (S, 2, H, W) moments as two contiguous (S, H, W) halves (scratch: layout is free).
        halves = stale["history_moments"].reshape(2, s, h, w)
        run.borrowed = {
            "stale_colour": colour,
            "guide_luminance": halves[0],
            "guide_inverse_scale": halves[1],
            "variance_a": stale["history_length"],
        }
        shape = scratch_shape(s, h, w)
        size = int(np.prod(shape))
        if size <= colour.size:  # always but for images of a few pixels
            run.borrowed["antilag_scratch"] = colour.reshape(-1)[:size].reshape(shape)

    def _store_history(self, run: _FrameRun, illumination_name: str) -> None:
        """Hand this frame's buffers to the history by swapping (no copies); the workspace
        takes the stale history arrays and overwrites them next frame."""
        work, frame, counts = run.work, run.frame, run.counts
        history = self._history_buffers(work)
        self._history = history
        self._fresh_history = None
        colour = run.plane(illumination_name)
        for key, name in (
            ("history_illumination", illumination_name),
            ("history_moments", "moments"),
            ("history_length", "history_length"),
            ("history_mode", "mode"),
            ("prev_normal", "normal"),
        ):
            if key == "history_illumination" and colour is history[key]:
                continue  # the feedback iteration wrote into the stale history itself
            history[key], work.planes[name] = work.planes[name], history[key]
        # The frame's planes belong to the caller: copy.
        np.copyto(history["prev_depth"], run.depth)
        np.copyto(history["prev_mesh_id"], frame.mesh_id)
        counts["history_resets"] += values.reset_nonfinite_history(
            history["history_illumination"], history["history_moments"],
            history["history_length"], history["history_mode"],
        )


def _colour_slots(signals: list[Signal]) -> tuple[tuple[int, ...], list[int]]:
    """Which running mean each signal's demodulation colour has (-1: none), and the first
    signal of each: signals that share one colour array (a reader gives direct and indirect
    light the same colour pass) and its demodulation rule (``guide_albedo``) share a mean.
    Glossy signals keep this frame's colour: their light follows reflections, not the
    texture under it, and a specular colour is smooth (measured: no gain on the Blender
    fixtures, where averaging it cost a third of the stage)."""
    slots: list[int] = []
    sources: list[int] = []
    keys: list[tuple[int, bool]] = []
    for index, signal in enumerate(signals):
        if signal.glossy:
            slots.append(-1)
            continue
        key = (id(signal.albedo), signal.guide_albedo)
        if key not in keys:
            keys.append(key)
            sources.append(index)
        slots.append(keys.index(key))
    return tuple(slots), sources


def _colour_count(slots: tuple[int, ...]) -> int:
    """How many running means ``slots`` (:func:`_colour_slots`) name."""
    return len(set(slots) - {-1})


def _albedo_state(state: dict[str, np.ndarray], history: dict[str, np.ndarray] | None,
                  ) -> tuple[tuple[np.ndarray, np.ndarray] | None, tuple[int, ...]]:
    """The temporal albedo's history in a saved state (``albedo_history``, ``_length``,
    ``_slots``), checked against the history; ``(None, ())`` when it has none."""
    keys = ("albedo_history", "albedo_length", "albedo_slots")
    if history is None or not all(key in state for key in keys):
        return None, ()
    colour = np.array(state["albedo_history"], dtype=F32, copy=True, order="C")
    length = np.array(state["albedo_length"], dtype=F32, copy=True, order="C")
    slots = tuple(int(v) for v in np.asarray(state["albedo_slots"]).ravel())
    height, width = history["prev_depth"].shape
    count = colour.shape[0] if colour.ndim == 4 else -1
    if (colour.shape != (count, 3, height, width) or length.shape != (count, height, width)
            or len(slots) != len(history["history_length"])
            or sorted(set(slots) - {-1}) != list(range(count))):
        raise ValueError("denoiser state albedo_history does not match the history")
    if not (np.isfinite(colour).all() and np.isfinite(length).all()):
        raise ValueError("denoiser state albedo_history has non-finite values")
    return (colour, length), slots


def _add(counts: dict[str, int], kind: str, plane: str, value: int) -> None:
    """Add to a total (``kind``) and, when non-zero, to its per-plane breakdown."""
    counts[kind] = counts.get(kind, 0) + value
    if value:
        counts[f"{kind}.{plane}"] = counts.get(f"{kind}.{plane}", 0) + value


def signal_sigma_luminance(params: SVGFParams, signal: Signal) -> float:
    """The a-trous luminance stop of ``signal``: glossy signals' own, else mixed signals'
    own (direct and indirect light together), else ``sigma_luminance``."""
    if signal.glossy:
        return params.glossy_sigma_luminance or params.sigma_luminance
    if signal.mixed:
        return params.mixed_sigma_luminance or params.sigma_luminance
    return params.sigma_luminance


def signal_groups(num_signals: int) -> list[slice]:
    """The a-trous filters signals in groups sharing the geometric weights: threes, but
    4 as 2 + 2 (a lone signal costs nearly as much as a pair), and 1 or 2 as they are."""
    sizes: list[int] = []
    left = num_signals
    while left > 0:
        size = 2 if left in (2, 4) else min(left, 3)
        sizes.append(size)
        left -= size
    starts = np.cumsum([0, *sizes])
    return [slice(int(a), int(b)) for a, b in zip(starts[:-1], starts[1:], strict=True)]


def _gradient_samples(
    frame: Frame,
) -> list[tuple[np.ndarray, np.ndarray, np.ndarray] | None] | None:
    """Per signal, its temporal gradient samples as (mask, previous, current), or None;
    a sample with a non-finite value is no sample. None when no signal has any."""
    if all(signal.gradient is None for signal in frame.signals):
        return None
    samples: list[tuple[np.ndarray, np.ndarray, np.ndarray] | None] = []
    for signal in frame.signals:
        gradient = signal.gradient
        if gradient is None:
            samples.append(None)
            continue
        finite = np.isfinite(gradient.previous) & np.isfinite(gradient.current)
        mask = np.where(finite & (gradient.mask > 0), F32(1.0), F32(0.0))
        samples.append((mask, np.where(finite, gradient.previous, F32(0.0)),
                        np.where(finite, gradient.current, F32(0.0))))
    return samples


def _cells_to_pixels(cells: np.ndarray, height: int, width: int) -> np.ndarray:
    """A per-cell (2x2 pixels) plane at pixel resolution (for the debug layers)."""
    return np.ascontiguousarray(np.repeat(np.repeat(cells, 2, 0), 2, 1)[:height, :width])


def _writable(frame: Frame) -> Frame:
    """The frame with read-only planes copied: numba compiles a separate version of every
    kernel for read-only arrays, which would double the JIT time for no benefit."""

    def own(plane: np.ndarray) -> np.ndarray:
        return plane if plane.flags.writeable else plane.copy()

    planes = {}
    for f in dataclasses.fields(frame):
        plane = getattr(frame, f.name)
        if isinstance(plane, np.ndarray) and not plane.flags.writeable:
            planes[f.name] = plane.copy()
    if any(not s.radiance.flags.writeable or not s.albedo.flags.writeable
           for s in frame.signals):
        planes["signals"] = [
            dataclasses.replace(s, radiance=own(s.radiance), albedo=own(s.albedo))
            for s in frame.signals
        ]
    return dataclasses.replace(frame, **planes) if planes else frame


def _check_params(p: SVGFParams) -> None:
    if p.atrous_iterations < 0 and p.atrous_iterations != AUTO_ITERATIONS:
        raise ValueError(f"atrous_iterations must be >= 0 or {AUTO_ITERATIONS} (auto)")
    if p.atrous_iterations > 12:
        raise ValueError("atrous_iterations must be <= 12 (step 4096)")
    if not 0.0 < p.alpha <= 1.0 or not 0.0 < p.moments_alpha <= 1.0:
        raise ValueError("alpha and moments_alpha must lie in (0, 1]")
    if p.history_cap < 1:
        raise ValueError("history_cap must be >= 1")
    if p.sigma_normal <= 0.0 or p.sigma_luminance <= 0.0 or p.sigma_depth <= 0.0:
        raise ValueError("sigma_normal, sigma_luminance and sigma_depth must be > 0")
    if p.spatial_variance_sigma_luminance <= 0.0 or p.spatial_variance_radius < 0:
        raise ValueError("spatial variance sigma must be > 0 and radius >= 0")
    if p.albedo_epsilon <= 0.0:
        raise ValueError("albedo_epsilon must be > 0")
    if not 0.0 <= p.guide_albedo_floor <= 1.0:
        raise ValueError("guide_albedo_floor must lie in [0, 1]")
    if not 0.0 <= p.moving_feedback_share <= 1.0:
        raise ValueError("moving_feedback_share must lie in [0, 1]")
    if not 0.0 < p.taa_alpha <= 1.0:
        raise ValueError("taa_alpha must lie in (0, 1]")
    if p.pixel_filter != AUTO_PIXEL_FILTER and not 0.0 <= p.pixel_filter <= 1.0 / 3.0:
        raise ValueError(f"pixel_filter must lie in [0, 1/3] or be {AUTO_PIXEL_FILTER} (auto)")
    if 0.0 < p.despike < 1.0:
        raise ValueError("despike must be 0 (off) or >= 1 (a ratio to the neighbours)")


def _encode(text: str) -> np.ndarray:
    return np.frombuffer(text.encode("utf-8"), dtype=np.uint8).copy()


def _decode(array: np.ndarray) -> str:
    return np.asarray(array, dtype=np.uint8).tobytes().decode("utf-8")
