"""ColorVideoVDP (Mantiuk et al. 2024): video and still JOD of a sequence against its reference.

JOD = just-objectionable differences: 10 = no visible difference; one JOD less means about
75 % of observers prefer the other. The metric models spatial *and* temporal contrast
sensitivity, so it sees blur and flicker (low-frequency boiling, crawling edges) the way a
viewer does, where the per-pixel temporal error weighs every change alike.

Inputs are the display images of :func:`svgf_cli.evaluate.metrics.tone_map` (Reinhard, then
the sRGB transfer function; the same mapping for test and reference), shaped frames x H x W x
3 in [0, 1]. The metric reads them as display-encoded SDR on its ``standard_fhd`` display
(sRGB EOTF, 200 cd/m^2 peak, 24" full HD at 60 cm), at 24 frames per second.

The metric (PyPI ``cvvdp``, import ``pycvvdp``) needs PyTorch: an optional extra
(``pip install 'svgf[perceptual]'``, which ``make results`` installs). Everything here
imports torch lazily, inside functions; without it :func:`load_metric` raises a UsageError
with the install command.
"""

from __future__ import annotations

import math
import sys
import types
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

from svgf_cli.errors import UsageError

DISPLAY = "standard_fhd"
FRAMES_PER_SECOND = 24.0
HEATMAP = "supra-threshold"

JOD_MISSING = (
    "--jod needs ColorVideoVDP and PyTorch: pip install 'svgf[perceptual]' "
    "(packages cvvdp and torch; `make results` installs them)"
)

JOD_DESCRIPTION = (
    f"ColorVideoVDP (cvvdp), display {DISPLAY!r}, {FRAMES_PER_SECOND:g} fps, on the "
    "tone-mapped display images (frames x H x W x 3 in [0, 1]); video JOD: the scored frames "
    "as one video; still JOD: mean over frames of each frame alone"
)


class JodMetric(Protocol):
    """What :func:`jod_scores` needs of ``pycvvdp.cvvdp``."""

    def predict(self, test: Any, reference: Any, dim_order: str = ...,
                frames_per_second: float = ...) -> tuple[Any, dict]: ...


@dataclass
class JodScore:
    """One method's JOD: the video as a whole, and each frame as a still image."""

    video: float
    still_frames: list[float] = field(default_factory=list)
    heatmap: np.ndarray | None = None  # (F, H, W, 3) in [0, 1] when asked for

    @property
    def still(self) -> float:
        """Mean still JOD over the frames."""
        return math.fsum(self.still_frames) / len(self.still_frames)


def as_video(frames: Sequence[np.ndarray]) -> np.ndarray:
    """Display frames, each (3, H, W) (or (H, W, 3)), as one float32 array frames x H x W x 3
    in [0, 1] (what the metric reads with ``dim_order='FHWC'``)."""
    if not frames:
        raise ValueError("no frames")
    stacked = []
    for frame in frames:
        array = np.asarray(frame, dtype=np.float32)
        if array.ndim != 3 or 3 not in (array.shape[0], array.shape[-1]):
            raise ValueError(f"expected (3, H, W) or (H, W, 3) frames, got {array.shape}")
        stacked.append(np.moveaxis(array, 0, -1) if array.shape[0] == 3 and
                       array.shape[-1] != 3 else array)  # fmt: skip
    video = np.stack(stacked)
    if not np.isfinite(video).all():
        raise ValueError("frames hold NaN or infinite values")
    return np.ascontiguousarray(np.clip(video, 0.0, 1.0), dtype=np.float32)


def _tensor(array: np.ndarray) -> Any:
    """A torch tensor of ``array`` when torch is installed, else the array (fake metrics)."""
    try:
        import torch
    except ImportError:
        return array
    return torch.from_numpy(array)


def _number(value: Any) -> float:
    return float(value.item() if hasattr(value, "item") else value)


def jod_scores(test: Sequence[np.ndarray], reference: Sequence[np.ndarray], metric: JodMetric,
               fps: float = FRAMES_PER_SECOND, stills: bool = True) -> JodScore:
    """Video JOD of ``test`` against ``reference`` (display frames, see :func:`as_video`) and
    the still JOD of every frame (``stills``). With a heat-map metric (``load_metric(
    heatmap=True)``) the score carries the video's map of where the differences are."""
    video_test, video_ref = as_video(test), as_video(reference)
    if video_test.shape != video_ref.shape:
        raise ValueError(f"shape mismatch {video_test.shape} vs {video_ref.shape}")
    if len(video_test) > 1:
        jod, stats = metric.predict(_tensor(video_test), _tensor(video_ref), dim_order="FHWC",
                                    frames_per_second=fps)  # fmt: skip
    else:
        jod, stats = metric.predict(_tensor(video_test[0]), _tensor(video_ref[0]),
                                    dim_order="HWC")  # fmt: skip
    score = JodScore(_number(jod))
    heat = stats.get("heatmap") if isinstance(stats, dict) else None
    if heat is not None:  # (1, 3, F, H, W) float16
        array = np.asarray(heat.float().numpy() if hasattr(heat, "float") else heat)
        score.heatmap = np.clip(np.moveaxis(array[0], 0, -1), 0.0, 1.0).astype(np.float32)
    if stills:
        for t, r in zip(video_test, video_ref, strict=True):
            jod, _ = metric.predict(_tensor(t), _tensor(r), dim_order="HWC")
            score.still_frames.append(_number(jod))
    else:
        score.still_frames.append(score.video)
    return score


def load_metric(heatmap: bool = False) -> JodMetric:
    """``pycvvdp.cvvdp`` on the CPU, display ``standard_fhd`` (with the supra-threshold heat
    map when ``heatmap``); UsageError with the install command when it is missing."""
    try:
        import torch
    except ImportError as exc:
        raise UsageError(JOD_MISSING) from exc
    _ensure_torchvision()
    try:
        import pycvvdp
    except ImportError as exc:
        raise UsageError(JOD_MISSING) from exc
    import logging

    logging.getLogger().setLevel(max(logging.getLogger().level, logging.WARNING))
    return pycvvdp.cvvdp(display_name=DISPLAY, device=torch.device("cpu"), quiet=True,
                         heatmap=HEATMAP if heatmap else None)  # fmt: skip


def _ensure_torchvision() -> None:
    """cvvdp imports ``torchvision.transforms.GaussianBlur`` (and ``torchvision.ops.MLP`` for
    its ML variants, unused here). A CPU-only torch build next to PyPI's torchvision (built for
    CUDA torch) cannot load torchvision's operators; then a stand-in module provides the one
    class cvvdp uses, the same Gaussian blur (torchvision's kernel, reflect padding)."""
    try:
        import torchvision.transforms  # noqa: F401
        return
    except Exception:  # noqa: BLE001 - any failure to load its compiled operators
        for name in [n for n in sys.modules if n == "torchvision" or
                     n.startswith("torchvision.")]:  # fmt: skip
            del sys.modules[name]
    package = types.ModuleType("torchvision")
    transforms = types.ModuleType("torchvision.transforms")
    ops = types.ModuleType("torchvision.ops")
    transforms.GaussianBlur = _gaussian_blur_class()  # type: ignore[attr-defined]
    ops.MLP = None  # type: ignore[attr-defined]
    package.transforms, package.ops = transforms, ops  # type: ignore[attr-defined]
    sys.modules.update({"torchvision": package, "torchvision.transforms": transforms,
                        "torchvision.ops": ops})  # fmt: skip


def _gaussian_blur_class() -> type:
    import torch

    class GaussianBlur(torch.nn.Module):
        """torchvision's GaussianBlur with a fixed sigma: separable, reflect-padded."""

        def __init__(self, kernel_size: int, sigma: float) -> None:
            super().__init__()
            half = (kernel_size - 1) * 0.5
            x = torch.linspace(-half, half, steps=kernel_size)
            pdf = torch.exp(-0.5 * (x / sigma).pow(2))
            self.kernel = pdf / pdf.sum()
            self.size = kernel_size

        def forward(self, image: torch.Tensor) -> torch.Tensor:
            shape = image.shape
            flat = image.reshape(-1, 1, shape[-2], shape[-1])
            k = self.kernel.to(device=image.device, dtype=image.dtype)
            pad = self.size // 2
            flat = torch.nn.functional.pad(flat, [pad, pad, pad, pad], mode="reflect")
            flat = torch.nn.functional.conv2d(flat, k.view(1, 1, 1, -1))
            flat = torch.nn.functional.conv2d(flat, k.view(1, 1, -1, 1))
            return flat.reshape(shape)

    return GaussianBlur
