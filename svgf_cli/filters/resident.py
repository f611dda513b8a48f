"""What a filter keeps between frames: the history, the workspace and the colour means.

``state()`` / ``load_state()`` save and restore the history (layout :data:`STATE_FORMAT`);
:meth:`Resident.held_bytes` is the filter's share of a run's memory.
"""

from __future__ import annotations

import json
from dataclasses import dataclass

import numpy as np

from svgf_cli.filters import values
from svgf_cli.filters.buffers import HISTORY_SHAPES, Workspace, fresh_history
from svgf_cli.filters.params import SVGFParams

F32 = np.float32

# Version of the state() layout: 2 = per-signal history length and modes, named signals.
STATE_FORMAT = 2


@dataclass
class Resident:
    """The arrays a filter keeps between frames (the buffers' table: ``filters.buffers``).

    ``history`` is last frame's history (None before the first frame); ``fresh`` a set of
    history arrays allocated before there is any history (the first frame lends them as
    scratch; ``store_history`` adopts them). ``albedo`` is the temporal albedo's running mean
    (U, 3, H, W) and length (U, H, W) per distinct demodulation colour and ``albedo_slots``
    which colour each signal has; ``forward_albedo`` a reverse pass's forward colour means
    (from ``forward_buffers`` to the end of the output frame).
    """

    work: Workspace | None = None
    signal_names: tuple[str, ...] | None = None
    history: dict[str, np.ndarray] | None = None
    fresh: dict[str, np.ndarray] | None = None
    taa_previous: np.ndarray | None = None
    # A still light's emission means (filters.emission_mean): mean, length, still, level.
    emission_mean: dict[str, np.ndarray] | None = None
    albedo: tuple[np.ndarray, np.ndarray] | None = None
    albedo_slots: tuple[int, ...] = ()
    forward_albedo: tuple[np.ndarray, np.ndarray] | None = None
    frames_processed: int = 0

    def reset(self) -> None:
        """Drop all history: the next frame is processed cold."""
        self.history = None
        self.taa_previous = None
        self.emission_mean = None
        self.albedo = None
        self.albedo_slots = ()
        self.signal_names = None
        self.frames_processed = 0

    def held_bytes(self) -> int:
        """Bytes of the arrays kept between frames, each counted once."""
        arrays: list[np.ndarray] = []
        for group in (self.history, self.fresh,
                      self.work.planes if self.work is not None else None):
            arrays += list(group.values()) if group is not None else []
        for pair in (self.albedo, self.forward_albedo):
            arrays += list(pair) if pair is not None else []
        if self.taa_previous is not None:
            arrays.append(self.taa_previous)
        arrays += list(self.emission_mean.values()) if self.emission_mean is not None else []
        return sum({id(array): array.nbytes for array in arrays}.values())

    def resolution(self) -> tuple[int, int] | None:
        if self.history is not None:
            h, w = self.history["prev_depth"].shape
            return int(w), int(h)
        if self.taa_previous is not None:
            return int(self.taa_previous.shape[2]), int(self.taa_previous.shape[1])
        return None

    def release_workspace(self) -> None:
        """Let go of the per-frame planes (the next frame allocates them afresh, zeroed): they
        are scratch, so outputs are the same; a caller running two filters one after the
        other holds one workspace at a time instead of two."""
        self.work = None

    def workspace(self, height: int, width: int, num_signals: int) -> Workspace:
        """The workspace for this size (a new one when the signal count changes)."""
        previous = self.resolution()
        if previous is not None and previous != (width, height):
            raise ValueError(
                f"resolution changed from {previous[0]}x{previous[1]} to {width}x{height}"
            )
        work = self.work
        if work is None or (work.height, work.width, work.num_signals) != (
            height, width, num_signals
        ):
            work = Workspace(height, width, num_signals)
            self.work = work
        return work

    def history_buffers(self, work: Workspace) -> dict[str, np.ndarray]:
        """The history arrays: last frame's history, or before there is one a fresh set that
        ``store_history`` adopts (so the first frame's scratch is no extra memory)."""
        shape = HISTORY_SHAPES["history_illumination"][0](work.num_signals, work.height,
                                                          work.width)
        history = self.history
        if history is not None and history["history_illumination"].shape == shape:
            return history
        fresh = self.fresh
        if fresh is None or fresh["history_illumination"].shape != shape:
            fresh = fresh_history(work.num_signals, work.height, work.width)
            self.fresh = fresh
        return fresh

    def forward_albedo_buffers(self, count: int, height: int,
                               width: int) -> tuple[np.ndarray, np.ndarray]:
        """Where a bidirectional reverse pass puts the forward pass's ``count`` colour
        means (kept from frame to frame)."""
        shape = (count, 3, height, width)
        if self.forward_albedo is None or self.forward_albedo[0].shape != shape:
            self.forward_albedo = (np.zeros(shape, dtype=F32),
                                   np.zeros((count, height, width), dtype=F32))
        return self.forward_albedo

    def state(self, params: SVGFParams) -> dict[str, np.ndarray]:
        """Everything needed to continue the sequence bit-identically (copies)."""
        state: dict[str, np.ndarray] = {
            "format_version": np.array(STATE_FORMAT, dtype=np.int64),
            "params": _encode(params.to_json()),
            "frames_processed": np.array(self.frames_processed, dtype=np.int64),
        }
        if self.signal_names is not None:
            state["signals"] = _encode(",".join(self.signal_names))
        if self.history is not None:
            for key in HISTORY_SHAPES:
                state[key] = self.history[key].copy()
        if self.taa_previous is not None:
            state["taa_previous"] = self.taa_previous.copy()
        for key, plane in (self.emission_mean or {}).items():
            state[f"emission_mean_{key}"] = plane.copy()
        if self.albedo is not None:
            state["albedo_history"] = self.albedo[0].copy()
            state["albedo_length"] = self.albedo[1].copy()
            state["albedo_slots"] = np.array(self.albedo_slots, dtype=np.int64)
        return state

    def load_state(self, params: SVGFParams, state: dict[str, np.ndarray]) -> None:
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
        if json.loads(saved_params) != json.loads(params.to_json()):
            raise ValueError("denoiser state was saved with different parameters")
        names = tuple(_decode(state["signals"]).split(",")) if "signals" in state else None
        history = _history_state(state, names)
        taa_previous = None
        if "taa_previous" in state:
            taa_previous = np.array(state["taa_previous"], dtype=F32, copy=True, order="C")
            if history is not None and taa_previous.shape[1:] != history["prev_depth"].shape:
                raise ValueError("denoiser state taa_previous does not match the history shape")
        albedo, slots = _albedo_state(state, history)
        self.history = history
        self.taa_previous = taa_previous
        self.emission_mean = _emission_mean_state(state, history)
        self.albedo, self.albedo_slots = albedo, slots
        self.signal_names = names
        self.frames_processed = frames


def _history_state(state: dict[str, np.ndarray],
                   names: tuple[str, ...] | None) -> dict[str, np.ndarray] | None:
    """The history arrays of a saved state, checked and cleaned (None: it has none)."""
    if "history_illumination" not in state:
        return None
    if names is None:
        raise ValueError("denoiser state has history but no signal names")
    missing = [k for k in HISTORY_SHAPES if k not in state]
    if missing:
        raise ValueError(f"denoiser state lacks {', '.join(missing)}")
    height, width = np.asarray(state["prev_depth"]).shape
    history = {}
    for key, (shape_of, dtype) in HISTORY_SHAPES.items():
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
    return history


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


def _encode(text: str) -> np.ndarray:
    return np.frombuffer(text.encode("utf-8"), dtype=np.uint8).copy()


def _decode(array: np.ndarray) -> str:
    return np.asarray(array, dtype=np.uint8).tobytes().decode("utf-8")


_EMISSION_MEAN = {"mean": F32, "length": F32, "still": np.uint8, "level": F32}


def _emission_mean_state(state: dict[str, np.ndarray], history: dict[str, np.ndarray] | None
                         ) -> dict[str, np.ndarray] | None:
    """The emission means of a saved state (None: it has none), checked."""
    keys = [k for k in _EMISSION_MEAN if f"emission_mean_{k}" in state]
    if not keys:
        return None
    if len(keys) != len(_EMISSION_MEAN):
        raise ValueError("denoiser state has part of the emission means")
    planes = {k: np.array(state[f"emission_mean_{k}"], dtype=t, copy=True, order="C")
              for k, t in _EMISSION_MEAN.items()}
    shape = planes["length"].shape
    if (planes["mean"].shape != (3, *shape)
            or any(planes[k].shape != shape for k in ("still", "level"))
            or (history is not None and shape != history["prev_depth"].shape)):
        raise ValueError("denoiser state emission means do not match the history shape")
    return planes
