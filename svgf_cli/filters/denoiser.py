"""The SVGF denoiser: owns the history buffers and runs the stages in order.

Per frame: geometry gradients -> demodulate (+ optional firefly clamp) -> reproject the
history (+ optional history clamp) -> accumulate -> variance -> a-trous iterations (the
``feedback_iteration`` output becomes next frame's colour history) -> remodulate, add
emission, sum the signals, restore background -> optional TAA.

All buffers are float32 structure-of-arrays planes, allocated once per resolution and
reused, so memory does not grow with the sequence length. Scratch is shared between stages
(names are roles; a buffer is taken on first use): the reprojected history is accumulated in
place, the a-trous ping-pong reuses the demodulated illumination once it is dead, the
reprojection thresholds live in the a-trous variance buffers until those are needed, and the
output radiance is a fresh array per frame handed to the caller (no resident copy).
At 1080p with two signals the resident set is about 60 float32 planes (~0.5 GB) including
the history.
"""

from __future__ import annotations

import dataclasses
import json
import time
from dataclasses import dataclass, field

import numpy as np

from svgf_cli.filters.atrous import atrous_iteration, luminance_stop_guides
from svgf_cli.filters.clamp import firefly_clamp, history_clamp
from svgf_cli.filters.edges import normal_squarings
from svgf_cli.filters.gradients import depth_gradients, normal_gradient, unit_normals
from svgf_cli.filters.modulate import (
    demodulate,
    filter_normals,
    remodulate,
    remodulate_add,
    restore_background,
)
from svgf_cli.filters.params import SVGFParams
from svgf_cli.filters.reproject import accumulate_in_place, reproject
from svgf_cli.filters.taa import taa_resolve
from svgf_cli.filters.variance import estimate_variance
from svgf_cli.frame import DenoisedFrame, Frame

F32 = np.float32

# Arrays that make up the persistent history; state() returns exactly these (plus metadata).
_HISTORY_KEYS = (
    "history_illumination",
    "history_moments",
    "history_length",
    "prev_depth",
    "prev_normal",
    "prev_mesh_id",
)


# Illumination-shaped (S, 3, H, W) scratch roles, in order of preference for a-trous outputs.
_ILLUMINATION_SCRATCH = ("demodulated", "accumulated", "spare_a", "spare_b", "spare_c")


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

    def shape(self, name: str) -> tuple[int, ...]:
        h, w, s = self.height, self.width, self.num_signals
        if name in _ILLUMINATION_SCRATCH:
            return (s, 3, h, w)
        shapes: dict[str, tuple[int, ...]] = {
            "normal": (3, h, w),
            "filter_normal": (3, h, w),
            "ddx": (h, w),
            "ddy": (h, w),
            # resampled and then (in place) accumulated moments and history length
            "moments": (s, 2, h, w),
            "history_length": (h, w),
            "variance": (s, h, w),
            "variance_a": (s, h, w),
            "variance_b": (s, h, w),
            "guide_luminance": (s, h, w),
            "guide_inverse_scale": (s, h, w),
            "taa": (3, h, w),
        }
        return shapes[name]

    def __getitem__(self, name: str) -> np.ndarray:
        plane = self.planes.get(name)
        if plane is None:
            plane = np.zeros(self.shape(name), dtype=F32)
            self.planes[name] = plane
        return plane


class Denoiser:
    """Spatiotemporal variance-guided filtering of a frame sequence (Schied et al. 2017).

    Feed frames in sequence order to :meth:`process`; the history persists between calls.
    ``stage_seconds`` holds the wall time of each stage of the last frame (for benchmarks).
    """

    def __init__(self, params: SVGFParams, debug_layers: bool = False) -> None:
        _check_params(params)
        self.params = params
        self.debug_layers = debug_layers
        self._squarings = normal_squarings(params.sigma_normal)
        self._work: _Workspace | None = None
        self._signal_names: tuple[str, ...] | None = None
        self._history: dict[str, np.ndarray] | None = None
        self._taa_previous: np.ndarray | None = None
        self._frames_processed = 0
        self.stage_seconds: dict[str, float] = {}

    # ----------------------------------------------------------------- public API
    @property
    def frames_processed(self) -> int:
        """Frames processed since construction or the last :meth:`reset`."""
        return self._frames_processed

    def reset(self) -> None:
        """Drop all history: the next frame is processed cold."""
        self._history = None
        self._taa_previous = None
        self._signal_names = None
        self._frames_processed = 0

    def process(self, frame: Frame) -> DenoisedFrame:
        """Denoise the next frame of the sequence."""
        frame.validate()
        frame = _writable(frame)
        signals = frame.signals()
        names = tuple(name for name, _ in signals)
        height, width = frame.height, frame.width
        work = self._workspace(height, width, len(signals))
        if self._signal_names is not None and self._signal_names != names:
            raise ValueError(
                f"signals changed from {'+'.join(self._signal_names)} to {'+'.join(names)}"
            )
        self._signal_names = names
        p = self.params
        timings: dict[str, float] = {}
        clock = time.perf_counter()

        def lap(stage: str) -> None:
            nonlocal clock
            now = time.perf_counter()
            timings[stage] = timings.get(stage, 0.0) + now - clock
            clock = now

        depth = frame.depth
        normal = work["normal"]
        unit_normals(frame.normal, depth, normal)
        # The reprojection thresholds are only needed until the a-trous writes variance:
        # they borrow its variance buffers (one (H, W) plane each, also with one signal).
        depth_slope = work["variance_a"][0]
        normal_width = work["variance_b"][0]
        depth_gradients(depth, work["ddx"], work["ddy"], depth_slope)
        normal_gradient(normal, depth, normal_width)
        # Spatial weights use filter_normal (negated where not demodulated); reprojection
        # compares the true normals.
        filter_normal = work["filter_normal"]
        filter_normals(normal, frame.albedo, F32(p.albedo_epsilon), filter_normal)
        lap("gradients")

        # Demodulate each signal; emission belongs to direct (split) or color (combined).
        emission = frame.emission
        has_emission = emission is not None
        # Without emission any (3, H, W) float32 plane will do: the kernels never read it.
        emission_plane = emission if emission is not None else frame.albedo
        eps = F32(p.albedo_epsilon)
        illumination = work["demodulated"]
        for index, (_, signal) in enumerate(signals):
            demodulate(signal, emission_plane, has_emission and index == 0, frame.albedo, eps,
                       illumination[index])
        if p.firefly_clamp > 0.0:
            firefly_clamp(illumination, depth, F32(p.firefly_clamp), work["spare_a"])
            illumination = work["spare_a"]
        lap("demodulate")

        # Reproject into the accumulation buffers and accumulate in place (element-wise).
        accumulated = work["accumulated"]
        moments = work["moments"]
        history_length = work["history_length"]
        history = self._history
        if p.temporal and history is not None:
            reproject(
                frame.motion, depth, normal, frame.mesh_id, depth_slope, normal_width,
                history["prev_depth"], history["prev_normal"], history["prev_mesh_id"],
                history["history_illumination"], history["history_moments"],
                history["history_length"], F32(p.depth_tolerance), F32(p.depth_slack),
                F32(p.normal_tolerance), accumulated, moments, history_length,
            )
            if p.history_clamp > 0.0:
                history_clamp(accumulated, history_length, illumination, depth,
                              F32(p.history_clamp))
        else:
            # Blend factor 1 everywhere; clear the stale contents (weight 0, but 0 * inf).
            history_length.fill(0.0)
            accumulated.fill(0.0)
            moments.fill(0.0)
        accumulate_in_place(
            illumination, accumulated, moments, history_length, depth, F32(p.alpha),
            F32(p.moments_alpha), F32(p.history_cap),
        )
        busy = {"accumulated"}  # the demodulated (and clamped) illumination is dead now
        lap("reproject")

        def scratch(*protected: str) -> str:
            """An illumination-shaped buffer name not in ``protected``."""
            for name in _ILLUMINATION_SCRATCH:
                if name not in protected:
                    return name
            raise AssertionError("out of scratch buffers")

        variance = work["variance"]
        filtered_name = "accumulated"
        blurred = None
        if p.spatial_variance_blur_color:
            filtered_name = scratch(*busy)
            blurred = work[filtered_name]
        estimate_variance(
            accumulated, moments, history_length, depth, work["ddx"], work["ddy"], filter_normal,
            history_threshold=float(p.variance_history_threshold),
            radius=p.spatial_variance_radius, sigma_depth=p.sigma_depth,
            sigma_luminance=p.spatial_variance_sigma_luminance, squarings=self._squarings,
            sigma_normal=p.sigma_normal, out_variance=variance, out_illumination=blurred,
        )
        lap("variance")

        # The colour history: the unfiltered accumulation unless an iteration feeds back.
        # That iteration's output is protected so later iterations cannot overwrite it.
        # The last iteration's propagated variance is never read, so it is not computed.
        feedback = min(p.feedback_iteration, p.atrous_iterations - 1)
        history_name = filtered_name
        filtered_name_now = filtered_name
        filtered = work[filtered_name]
        filtered_variance = variance
        # "variance" itself is reported as a debug layer; otherwise it is scratch after use.
        variance_names = ("variance_a", "variance_b")
        if not self.debug_layers:
            variance_names = ("variance_a", "variance", "variance_b")
        guide_luminance = work["guide_luminance"]
        guide_inverse_scale = work["guide_inverse_scale"]
        for iteration in range(p.atrous_iterations):
            luminance_stop_guides(filtered, filtered_variance, depth, F32(p.sigma_luminance),
                                  guide_luminance, guide_inverse_scale)
            out_name = scratch(filtered_name_now, history_name)
            if iteration == feedback:
                history_name = out_name
            propagate = iteration + 1 < p.atrous_iterations
            out_variance = filtered_variance  # not written when not propagated
            if propagate:
                out_variance = next(
                    work[v] for v in variance_names if work[v] is not filtered_variance
                )
            out_illumination = work[out_name]
            atrous_iteration(
                filtered, filtered_variance, guide_luminance, guide_inverse_scale, depth,
                work["ddx"], work["ddy"], filter_normal, 1 << iteration, p.sigma_depth,
                p.sigma_normal, propagate, out_illumination, out_variance,
            )
            filtered, filtered_variance = out_illumination, out_variance
            filtered_name_now = out_name
        lap("atrous")

        # Hand this frame's buffers to the history by swapping (no copies); the workspace
        # takes the stale history arrays and overwrites them next frame.
        self._store_history(frame, history_name)
        lap("reproject")

        # Remodulate, restore the background and sum the signals straight into a fresh
        # output array (handed to the caller, so nothing full-frame stays resident).
        radiance = np.zeros((3, height, width), dtype=F32)
        layers: dict[str, np.ndarray] = {}
        for index, (name, signal) in enumerate(signals):
            if self.debug_layers:
                signal_radiance = np.empty((3, height, width), dtype=F32)
                remodulate(filtered[index], emission_plane, has_emission and index == 0,
                           frame.albedo, eps, signal_radiance)
                restore_background(signal_radiance, signal, depth)
                radiance += signal_radiance
                for c, channel in enumerate("RGB"):
                    layers[f"{name}.{channel}"] = signal_radiance[c]
                layers[f"variance.{name}"] = variance[index].copy()
            else:
                remodulate_add(filtered[index], signal, emission_plane,
                               has_emission and index == 0, frame.albedo, eps, depth, radiance)
        if self.debug_layers:
            layers["history_length"] = history_length.copy()
        lap("modulate")

        if p.taa:
            if self._taa_previous is None:
                self._taa_previous = radiance.copy()
            else:
                taa_resolve(radiance, self._taa_previous, frame.motion, F32(p.taa_alpha),
                            work["taa"])
                np.copyto(self._taa_previous, work["taa"])
            output = self._taa_previous.copy()
            lap("taa")
        else:
            output = radiance

        self._frames_processed += 1
        self.stage_seconds = timings
        return DenoisedFrame(color=output, layers=layers)

    def state(self) -> dict[str, np.ndarray]:
        """Everything needed to continue the sequence bit-identically (copies)."""
        state: dict[str, np.ndarray] = {
            "params": _encode(self.params.to_json()),
            "frames_processed": np.array(self._frames_processed, dtype=np.int64),
        }
        if self._signal_names is not None:
            state["signals"] = _encode(",".join(self._signal_names))
        if self._history is not None:
            for key in _HISTORY_KEYS:
                state[key] = self._history[key].copy()
        if self._taa_previous is not None:
            state["taa_previous"] = self._taa_previous.copy()
        return state

    def load_state(self, state: dict[str, np.ndarray]) -> None:
        """Continue from :meth:`state`; ValueError if it was saved with other params/shapes."""
        try:
            saved_params = _decode(state["params"])
            frames = int(np.asarray(state["frames_processed"]))
        except (KeyError, TypeError, ValueError, UnicodeDecodeError) as exc:
            raise ValueError(f"not a denoiser state: {exc}") from exc
        if json.loads(saved_params) != json.loads(self.params.to_json()):
            raise ValueError("denoiser state was saved with different parameters")
        names = tuple(_decode(state["signals"]).split(",")) if "signals" in state else None
        history: dict[str, np.ndarray] | None = None
        if "history_illumination" in state:
            if names is None:
                raise ValueError("denoiser state has history but no signal names")
            missing = [k for k in _HISTORY_KEYS if k not in state]
            if missing:
                raise ValueError(f"denoiser state lacks {', '.join(missing)}")
            height, width = np.asarray(state["prev_depth"]).shape
            s = len(names)
            expected = {
                "history_illumination": ((s, 3, height, width), F32),
                "history_moments": ((s, 2, height, width), F32),
                "history_length": ((height, width), F32),
                "prev_depth": ((height, width), F32),
                "prev_normal": ((3, height, width), F32),
                "prev_mesh_id": ((height, width), np.int32),
            }
            history = {}
            for key, (shape, dtype) in expected.items():
                array = np.asarray(state[key])
                if array.shape != shape:
                    raise ValueError(f"denoiser state {key}: shape {array.shape}, expected {shape}")
                history[key] = np.array(array, dtype=dtype, copy=True, order="C")
        taa_previous = None
        if "taa_previous" in state:
            taa_previous = np.array(state["taa_previous"], dtype=F32, copy=True, order="C")
            if history is not None and taa_previous.shape[1:] != history["prev_depth"].shape:
                raise ValueError("denoiser state taa_previous does not match the history shape")
        self._history = history
        self._taa_previous = taa_previous
        self._signal_names = names
        self._frames_processed = frames

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

    def _store_history(self, frame: Frame, illumination_name: str) -> None:
        work = self._work
        assert work is not None
        history = self._history
        if history is None or history["history_illumination"].shape != (
            work[illumination_name].shape
        ):
            history = {
                "history_illumination": np.zeros_like(work[illumination_name]),
                "history_moments": np.zeros_like(work["moments"]),
                "history_length": np.zeros_like(work["history_length"]),
                "prev_depth": np.empty_like(frame.depth),
                "prev_normal": np.empty_like(work["normal"]),
                "prev_mesh_id": np.empty_like(frame.mesh_id),
            }
            self._history = history
        for key, name in (
            ("history_illumination", illumination_name),
            ("history_moments", "moments"),
            ("history_length", "history_length"),
            ("prev_normal", "normal"),
        ):
            history[key], work.planes[name] = work.planes[name], history[key]
        # The frame's planes belong to the caller: copy.
        np.copyto(history["prev_depth"], frame.depth)
        np.copyto(history["prev_mesh_id"], frame.mesh_id)


def _writable(frame: Frame) -> Frame:
    """The frame with read-only planes copied: numba compiles a separate version of every
    kernel for read-only arrays, which would double the JIT time for no benefit."""
    planes = {}
    for f in dataclasses.fields(frame):
        plane = getattr(frame, f.name)
        if isinstance(plane, np.ndarray) and not plane.flags.writeable:
            planes[f.name] = plane.copy()
    return dataclasses.replace(frame, **planes) if planes else frame


def _check_params(p: SVGFParams) -> None:
    if p.atrous_iterations < 0:
        raise ValueError("atrous_iterations must be >= 0")
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
    if not 0.0 < p.taa_alpha <= 1.0:
        raise ValueError("taa_alpha must lie in (0, 1]")


def _encode(text: str) -> np.ndarray:
    return np.frombuffer(text.encode("utf-8"), dtype=np.uint8).copy()


def _decode(array: np.ndarray) -> str:
    return np.asarray(array, dtype=np.uint8).tobytes().decode("utf-8")
