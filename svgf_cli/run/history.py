"""History files (``--save-history`` / ``--load-history``): a filter's state after the last
frame of a chunk, with what it was computed from (`HistoryFile`, `load_history`,
`save_history`), and the check that a loaded one fits the run's parameters
(`check_history_params`).
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from svgf_cli import __version__
from svgf_cli.errors import InputError, SvgfError, UsageError
from svgf_cli.filters.params import SVGFParams

_STATE_PREFIX = "state__"


@dataclass(frozen=True)
class HistoryFile:
    """A saved Denoiser state plus what it was computed from."""

    path: Path
    state: dict[str, np.ndarray]
    last_frame: int
    params_json: str
    width: int
    height: int


def load_history(path: Path) -> HistoryFile:
    """Read a ``--save-history`` file; InputError (exit 3) when missing or not one of ours."""
    try:
        with np.load(path, allow_pickle=False) as data:
            arrays = {name: np.array(data[name]) for name in data.files}
    except FileNotFoundError:
        raise InputError("history file not found", str(path)) from None
    except (OSError, ValueError) as exc:
        raise InputError(f"cannot read history file: {exc}", str(path)) from None
    try:
        last_frame = int(arrays["svgf_last_frame"])
        params_json = str(arrays["svgf_params"])
        height, width = (int(v) for v in arrays["svgf_shape"])
    except (KeyError, ValueError, TypeError):
        raise InputError("not an svgf history file (no svgf_* metadata)", str(path)) from None
    state = {
        name[len(_STATE_PREFIX) :]: value
        for name, value in arrays.items()
        if name.startswith(_STATE_PREFIX)
    }
    return HistoryFile(path, state, last_frame, params_json, width, height)


def save_history(
    path: Path,
    state: Mapping[str, np.ndarray],
    last_frame: int,
    params: SVGFParams,
    shape: tuple[int, int],
    last_input: Path,
) -> None:
    """Write the Denoiser state atomically (temp name, then rename)."""
    payload = {f"{_STATE_PREFIX}{k}": np.asarray(v) for k, v in state.items()}
    payload["svgf_last_frame"] = np.array(last_frame, dtype=np.int64)
    payload["svgf_params"] = np.array(params.to_json())
    payload["svgf_shape"] = np.array(shape, dtype=np.int64)
    payload["svgf_version"] = np.array(__version__)
    payload["svgf_input"] = np.array(str(last_input))
    from svgf_cli.io.atomic import atomic_target

    path.parent.mkdir(parents=True, exist_ok=True)
    try:
        with atomic_target(path) as tmp, open(tmp, "wb") as handle:
            np.savez(handle, **payload)
    except OSError as exc:
        raise SvgfError(f"cannot write history file: {exc.strerror or exc}", str(path)) from None


# Settings of the run, not of the filter whose state a history file holds: the look-ahead
# warm start of a cold start (a run that loads a history does not start cold).
NOT_IN_STATE = ("warm_start",)


def check_history_params(history: HistoryFile, params: SVGFParams) -> None:
    """Refuse a state computed with other parameters (exit 2), naming what differs (not
    the run-driver settings of :data:`NOT_IN_STATE`)."""
    if history.params_json == params.to_json():
        return
    try:
        saved = json.loads(history.params_json)
    except ValueError:
        saved = {}
    current = json.loads(params.to_json())
    for name in NOT_IN_STATE:
        saved.pop(name, None)
        current.pop(name, None)
    diffs = [
        f"{k} {saved.get(k)!r} (saved) != {current.get(k)!r}"
        for k in sorted(set(saved) | set(current))
        if saved.get(k) != current.get(k)
    ]
    if not diffs:
        return
    raise UsageError(
        "history was saved with different parameters: " + ("; ".join(diffs) or "unknown"),
        str(history.path),
    )
