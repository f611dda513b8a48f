"""What the Denoiser and a bidirectional run's passes share: a pipeline run frame by frame
over the arrays a filter keeps between frames (``filters.resident``)."""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from svgf_cli.filters import modulate
from svgf_cli.filters.context import FrameContext, Setup
from svgf_cli.filters.fastmath import float32_weights
from svgf_cli.filters.params import (
    SVGFParams,
    atrous_iterations_for,
    check_params,
    colour_blend_for,
    params_for_samples,
)
from svgf_cli.filters.pipeline import build
from svgf_cli.filters.resident import Resident
from svgf_cli.frame import Frame


class PipelineFilter:
    """A pipeline of ``kind`` (``filters.pipeline``) fed frames in sequence; the history
    persists between frames. ``stage_seconds`` / ``stage_cpu_seconds`` hold the wall and
    process CPU time of each stage of the last frame (for benchmarks)."""

    kind = "causal"

    def __init__(self, params: SVGFParams, debug_layers: bool = False) -> None:
        check_params(params)
        self.params = params
        self.debug_layers = debug_layers
        self.setup = Setup.of(params, debug_layers)
        # The setups of frames of several samples per pixel (params_for_samples), by count.
        self._setups: dict[int, Setup] = {}
        self.pipeline = build(params, self.kind)
        self.resident = Resident()
        self.stage_seconds: dict[str, float] = {}
        self.stage_cpu_seconds: dict[str, float] = {}
        self.stage_detail_seconds: dict[str, float] = {}

    @property
    def stages(self) -> tuple[str, ...]:
        """The names of the stages this filter runs, in order."""
        return self.pipeline.names

    @property
    def frames_processed(self) -> int:
        """Frames processed since construction or the last :meth:`reset`."""
        return self.resident.frames_processed

    @property
    def signal_names(self) -> tuple[str, ...] | None:
        """The signals of the sequence so far (None before the first frame)."""
        return self.resident.signal_names

    def held_bytes(self) -> int:
        """Bytes of the arrays this filter keeps between frames (history, workspace, colour
        means, TAA), each counted once: its share of a run's memory."""
        return self.resident.held_bytes()

    def reset(self) -> None:
        """Drop all history: the next frame is processed cold."""
        self.resident.reset()

    def state(self) -> dict[str, np.ndarray]:
        """Everything needed to continue the sequence bit-identically (copies)."""
        return self.resident.state(self.params)

    def load_state(self, state: dict[str, np.ndarray]) -> None:
        """Continue from :meth:`state`; ValueError if it was saved by another state format,
        with other parameters or with inconsistent shapes."""
        self.resident.load_state(self.params, state)

    def _run(self, frame: Frame, **fields: Any) -> FrameContext:
        """Run the pipeline on the next frame (``fields``: the context's inputs)."""
        ctx = self._start_frame(frame, **fields)
        self.pipeline.run(ctx)
        self.resident.frames_processed += 1
        self.stage_seconds = ctx.timings
        self.stage_cpu_seconds = ctx.cpu_timings
        self.stage_detail_seconds = ctx.stage_timings
        return ctx

    def _start_frame(self, frame: Frame, **fields: Any) -> FrameContext:
        """Check the frame against the sequence and open its workspace and stage clock."""
        frame.validate()
        frame = _writable(frame)
        names = frame.names
        if len(names) > modulate.MAX_SIGNALS:
            raise ValueError(f"at most {modulate.MAX_SIGNALS} signals, got {len(names)}")
        resident = self.resident
        if resident.signal_names is not None and resident.signal_names != names:
            raise ValueError(
                f"signals changed from {'+'.join(resident.signal_names)} to {'+'.join(names)}"
            )
        work = resident.workspace(frame.height, frame.width, len(names))
        resident.signal_names = names
        return FrameContext(frame, names, self._setup_for(frame.samples_per_pixel), resident,
                            work,
                            float32_weights(frame.luminance_weights),
                            atrous_iterations_for(self.params, frame.height, frame.width,
                                                  frame.samples_per_pixel),
                            **fields)

    def _setup_for(self, samples_per_pixel: int) -> Setup:
        """The setup of a frame of ``samples_per_pixel`` samples (its blends:
        ``params_for_samples``); the filter's own for one sample."""
        setup = self._setups.get(samples_per_pixel)
        if setup is None:
            params = params_for_samples(self.params, samples_per_pixel)
            albedo_blend = colour_blend_for(self.params, samples_per_pixel)
            setup = (self.setup if params is self.params
                     else dataclasses.replace(Setup.of(params, self.debug_layers, albedo_blend),
                                              signal_outputs=self.setup.signal_outputs))
            self._setups[samples_per_pixel] = setup
        return setup


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
