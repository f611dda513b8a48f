"""Side-by-side animations (input | svgf | OIDN | reference) and ColorVideoVDP heat maps.

Stills hide flicker; an animation shows it. Every panel is a display image of
:func:`svgf_cli.evaluate.metrics.tone_map` (the same mapping as the contact sheets and the
metrics), scaled up by a whole factor with nearest-neighbour sampling (pixels stay pixels),
under a label bar naming the method; the frame number is written in the first panel's bar.
Written with Pillow: an animated WebP (lossless) or GIF, chosen by the file's extension, that
loops forever. No ffmpeg needed.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

LABEL_HEIGHT = 14  # pixels of the label bar above each panel
GAP = 2  # pixels between panels
FRAMES_PER_SECOND = 8.0  # slow enough to follow one frame's change, fast enough to flicker


@dataclass(frozen=True)
class Panel:
    """One column of the animation: a label and its display frames ((3, H, W) in [0, 1])."""

    label: str
    frames: Sequence[np.ndarray]


def _rgb8(display: np.ndarray, scale: int) -> np.ndarray:
    """(3, H, W) or (H, W, 3) display image in [0, 1] -> uint8 (H*scale, W*scale, 3)."""
    array = np.asarray(display, dtype=np.float32)
    if array.shape[0] == 3 and array.shape[-1] != 3:
        array = np.moveaxis(array, 0, -1)
    array = np.clip(np.nan_to_num(array, nan=0.0), 0.0, 1.0)
    if scale > 1:
        array = np.repeat(np.repeat(array, scale, axis=0), scale, axis=1)
    return (array * 255.0 + 0.5).astype(np.uint8)


def compose_frame(panels: Sequence[Panel], index: int, scale: int = 1, title: str = "") -> object:
    """One animation frame: the panels' ``index``-th images side by side, labelled (a PIL
    image)."""
    from PIL import Image, ImageDraw

    images = [_rgb8(p.frames[index], scale) for p in panels]
    height, width = images[0].shape[:2]
    canvas = Image.new("RGB", (len(panels) * (width + GAP) - GAP, height + LABEL_HEIGHT))
    draw = ImageDraw.Draw(canvas)
    for column, (panel, image) in enumerate(zip(panels, images, strict=True)):
        if image.shape[:2] != (height, width):
            raise ValueError(f"panel {panel.label!r} is {image.shape[1]}x{image.shape[0]}, "
                             f"not {width}x{height}")  # fmt: skip
        left = column * (width + GAP)
        canvas.paste(Image.fromarray(image), (left, LABEL_HEIGHT))
        text = f"{title}  {panel.label}" if column == 0 and title else panel.label
        draw.text((left + 3, 1), text, fill=(255, 255, 255))
    return canvas


def write_animation(panels: Sequence[Panel], path: str | Path, scale: int = 2,
                    fps: float = FRAMES_PER_SECOND,
                    frame_numbers: Sequence[int] | None = None) -> int:
    """Write the panels as a looping animated WebP or GIF (by extension) and return its frame
    count. Every panel needs the same number of frames of one size."""
    counts = {len(p.frames) for p in panels}
    if not panels or len(counts) != 1 or 0 in counts:
        raise ValueError("every panel needs the same, nonzero number of frames")
    count = counts.pop()
    numbers = list(frame_numbers) if frame_numbers is not None else list(range(1, count + 1))
    images = [compose_frame(panels, i, scale, f"frame {numbers[i]}") for i in range(count)]
    target = Path(path)
    target.parent.mkdir(parents=True, exist_ok=True)
    duration = int(round(1000.0 / fps))
    options: dict[str, object] = {"save_all": True, "append_images": images[1:],
                                  "duration": duration, "loop": 0}  # fmt: skip
    suffix = target.suffix.lower()
    if suffix == ".webp":
        options.update(lossless=True, quality=80, method=4)
    elif suffix != ".gif":
        raise ValueError(f"{target}: write an animation as .webp or .gif")
    images[0].save(target, **options)  # type: ignore[attr-defined]
    return count


def write_heatmap(report: object, path: str | Path) -> None:
    """svgf's ColorVideoVDP heat map (supra-threshold colours over the reference), the mean
    over frames, as a PNG scaled up 2x."""
    from PIL import Image

    score = getattr(report, "jod", {}).get("svgf")
    if score is None or score.heatmap is None:
        raise ValueError("no heat map was measured for svgf")
    mean = np.mean(score.heatmap, axis=0)
    Image.fromarray(_rgb8(mean, 2)).save(Path(path))
