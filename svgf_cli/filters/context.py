"""The frame in flight through a pipeline, the stage protocol and the pipeline itself.

A stage (one module each under ``filters.stages``) has a ``name``, the buffer roles it
``reads`` and ``writes`` (``filters.buffers``), ``enabled(params)`` (whether the settings
include it) and ``run(ctx)`` on a :class:`FrameContext`; ``filters.pipeline`` puts them in
order. A stage's ``run`` returns False when it had nothing to do for this frame.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

from svgf_cli.filters.bidirectional import SideHistory, effective_counts
from svgf_cli.filters.buffers import Workspace
from svgf_cli.filters.edges import normal_squarings
from svgf_cli.filters.params import SVGFParams
from svgf_cli.filters.resident import Resident
from svgf_cli.frame import Frame

F32 = np.float32

# A demodulation colour whose brightest channel exceeds this is not a reflectance (1 plus a
# tolerance for pixel-filter overshoot and half-float storage): such pixels are filtered as
# radiance.
MAX_REFLECTANCE = 1.05
# Per-channel demodulation floor relative to the pixel's brightest albedo channel (bounds
# the remodulation gain within a pixel's colour; see filters.modulate and
# bench/demodulation_floor.py).
RELATIVE_ALBEDO_FLOOR = 0.02

Rule = tuple[np.float32, np.float32, np.float32]


@dataclass(frozen=True)
class Setup:
    """What every frame's stages derive from the settings once: the demodulation rules per
    ``guide_albedo``, the normal weight's squarings and the effective sample counts per
    history length (a bidirectional run's combination)."""

    params: SVGFParams
    debug_layers: bool
    rules: dict[bool, Rule]
    squarings: int
    colour_counts: np.ndarray
    moment_counts: np.ndarray
    # The demodulation colours' running means: their blend (``params.colour_blend_for``;
    # ``alpha`` at one sample) and its effective sample counts (a bidirectional run's).
    albedo_blend: float
    albedo_counts: np.ndarray
    # Return each signal's own remodulated radiance as the layers ``<signal>.R/G/B`` (the
    # light layers are composed from them: ``filters.composable``); implied by debug_layers.
    signal_outputs: bool = False

    @classmethod
    def of(cls, params: SVGFParams, debug_layers: bool,
           albedo_blend: float | None = None) -> Setup:
        """``albedo_blend``: the colours' running means' blend (None: ``params.alpha``)."""
        rules = {
            guide: (F32(max(params.albedo_epsilon, params.guide_albedo_floor if guide else 0.0)),
                    F32(MAX_REFLECTANCE), F32(RELATIVE_ALBEDO_FLOOR))
            for guide in (False, True)
        }
        albedo_blend = params.alpha if albedo_blend is None else albedo_blend
        return cls(params, debug_layers, rules, normal_squarings(params.sigma_normal),
                   effective_counts(params.alpha, params.history_cap),
                   effective_counts(params.moments_alpha, params.history_cap),
                   albedo_blend, effective_counts(albedo_blend, params.history_cap))


@dataclass
class TemporalState:
    """This frame's demodulated illumination and last frame's history resampled at its
    pixels, between reprojection and the blend (the views the temporal stages share).

    All arrays are the filter's own buffers, (S, ...) with one entry per signal, in the
    order of ``names``. ``history_length`` 0 = no history; ``mode`` is the (H, W) uint16
    mask of the demodulation modes (bit s set: signal s is filtered as radiance). A stage
    may change the history in place; lowering ``history_length[s]`` at a pixel raises that
    signal's blend factor there (``alpha = max(alpha, 1 / (h + 1))``).
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
class Spatial:
    """One spatial filtering (variance, then a-trous) of the accumulation in workspace
    buffer ``source``, and what it left: the filtered illumination (``name``), the colour
    history's buffer (``history_name``) and the variance entering the a-trous."""

    source: str
    moments: np.ndarray
    history_length: np.ndarray
    iterations: int
    protected: tuple[str, ...] = ()
    feeds_back: bool = True
    entering: str = ""  # the colour entering the a-trous (source, or the colour blur's)
    illumination: np.ndarray = field(default_factory=lambda: np.empty(0, F32))
    name: str = ""
    history_name: str = ""
    variance: np.ndarray = field(default_factory=lambda: np.empty(0, F32))


@dataclass
class FrameContext:
    """One frame in flight through a pipeline: the frame, the filter's settings and
    resident arrays, the planes earlier stages leave for later ones, the counts and the
    stage clock."""

    frame: Frame
    names: tuple[str, ...]
    setup: Setup
    resident: Resident
    work: Workspace
    weights: tuple[np.float32, np.float32, np.float32]
    iterations: int  # a-trous iterations at this frame's size (atrous_iterations_for)
    bidirectional: bool = False  # a pass of a bidirectional run
    counts: dict[str, int] = field(
        default_factory=lambda: {"nonfinite": 0, "extreme": 0, "history_resets": 0})
    depth: np.ndarray = field(default_factory=lambda: np.empty((0, 0), F32))
    normal_in: np.ndarray = field(default_factory=lambda: np.empty((3, 0, 0), F32))
    normal: np.ndarray = field(default_factory=lambda: np.empty((3, 0, 0), F32))
    motion: np.ndarray = field(default_factory=lambda: np.empty((2, 0, 0), F32))
    mode: np.ndarray = field(default_factory=lambda: np.empty((0, 0), np.uint16))
    # the reprojection thresholds (in the variance planes: filters.buffers.SHARING)
    depth_slope: np.ndarray = field(default_factory=lambda: np.empty((0, 0), F32))
    normal_width: np.ndarray = field(default_factory=lambda: np.empty((0, 0), F32))
    marked: dict[str, int] = field(default_factory=dict)  # reflected lights per signal
    # Per glossy signal's index, the objects whose reflections are sharp
    # (filters.reflected_albedo.SharpObjects; stages.reflected_albedo); absent: none.
    sharp_objects: dict[int, Any] = field(default_factory=dict)
    # ... and those whose reflections are rough (the same type); absent: none found.
    rough_objects: dict[int, Any] = field(default_factory=dict)
    # The pixels given a medium's G-buffer (filters.stages.fill_medium); None: none.
    medium_pixels: np.ndarray | None = None
    # The index of the medium's signal in ``frame.signals`` (fill_medium); None: none.
    medium_signal: int | None = None
    # The noisy outlines' exchanges the edge filter made (filters.edge_filter.OutlineSpill),
    # for the light layers to make the same; None: none.
    outline_spill: Any = None
    # Whether the frame's samples are jittered (filters.stages.taa.frame_is_jittered); None:
    # not worked out yet.
    jittered: bool | None = None
    # The pixels whose emission is a still light's mean (filters.stages.emission_mean).
    emission_averaged: np.ndarray | None = None
    illumination_name: str = "demodulated"  # the demodulated (+ clamped) frame
    temporal: TemporalState | None = None
    reprojected: bool = False  # there was a history to reproject
    # Scratch roles lent by last frame's history once it is reprojected (dead until
    # store_history replaces it); they take precedence over the workspace's own planes.
    borrowed: dict[str, np.ndarray] = field(default_factory=dict)
    keep: Any = None  # a forward pass: what to hand back of the resampled history
    # A turning object's history resampled at its translation, until it is adopted
    # (filters.stages.object_history).
    turned: Any = None
    kept: Any = None  # ... and what it handed back
    forward: SideHistory | None = None  # a reverse pass: the forward history here
    into: SideHistory | None = None  # ... and where it is combined
    history_name: str = ""  # the workspace buffer stored as the colour history
    spatial: Spatial | None = None
    output: np.ndarray | None = None
    layers: dict[str, np.ndarray] = field(default_factory=dict)
    timings: dict[str, float] = field(default_factory=dict)
    cpu_timings: dict[str, float] = field(default_factory=dict)
    # Wall seconds of each stage that ran, by its own name (the clocks above group several).
    stage_timings: dict[str, float] = field(default_factory=dict)
    clock: tuple[float, float] = field(
        default_factory=lambda: (time.perf_counter(), time.process_time()))

    @property
    def params(self) -> SVGFParams:
        return self.setup.params

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


class Stage(Protocol):
    """One step of a pipeline (``filters.stages``)."""

    name: str
    reads: tuple[str, ...]
    writes: tuple[str, ...]
    clock: str | None  # the stage_seconds entry its time adds to (None: it laps itself)

    def enabled(self, params: SVGFParams) -> bool: ...

    def run(self, ctx: FrameContext) -> bool | None: ...


class Pipeline:
    """Stages in order; :meth:`run` runs each on a frame and laps its clock."""

    def __init__(self, kind: str, stages: list[Stage]) -> None:
        self.kind = kind
        self.stages = stages

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(stage.name for stage in self.stages)

    def insert_after(self, name: str, stage: Stage) -> None:
        """Add ``stage`` after the stage called ``name`` (a test's extra stage)."""
        self.stages.insert(self.names.index(name) + 1, stage)

    def run(self, ctx: FrameContext) -> None:
        for stage in self.stages:
            started = time.perf_counter()
            if stage.run(ctx) is False:
                continue  # nothing to do on this frame: neither clock counts it
            if stage.clock is not None:
                ctx.lap(stage.clock)
            spent = time.perf_counter() - started
            ctx.stage_timings[stage.name] = ctx.stage_timings.get(stage.name, 0.0) + spent


def add_count(counts: dict[str, int], kind: str, plane: str, value: int) -> None:
    """Add to a total (``kind``) and, when non-zero, to its per-plane breakdown."""
    counts[kind] = counts.get(kind, 0) + value
    if value:
        counts[f"{kind}.{plane}"] = counts.get(f"{kind}.{plane}", 0) + value


class StageBase:
    """Defaults of the :class:`Stage` protocol: always enabled, reads and writes nothing."""

    name = ""
    reads: tuple[str, ...] = ()
    writes: tuple[str, ...] = ()
    clock: str | None = None

    def enabled(self, params: SVGFParams) -> bool:
        return True

    def run(self, ctx: FrameContext) -> bool | None:
        raise NotImplementedError


class OnOutputFrames(StageBase):
    """``stage`` on the reverse pass's output frames only (those given a forward history)."""

    def __init__(self, stage: Stage) -> None:
        self.stage = stage
        self.name, self.reads, self.writes = stage.name, stage.reads, stage.writes
        self.clock = stage.clock

    def enabled(self, params: SVGFParams) -> bool:
        return self.stage.enabled(params)

    def run(self, ctx: FrameContext) -> bool | None:
        if ctx.forward is None:
            return False
        return self.stage.run(ctx)
