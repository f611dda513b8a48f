"""The contact sheet: for chosen frames, every method side by side with the reference.

Columns: noisy input (when given), svgf, each baseline, the reference, and the FLIP error
map of the svgf output (magma: black = no visible difference, yellow = maximal). All images
are the tone-mapped display images the perceptual metrics see. Each cell is labelled with the
method and its relMSE and FLIP on that frame.
"""

from __future__ import annotations

import os
from collections.abc import Sequence

import numpy as np

from svgf_cli.evaluate.engine import INPUT, SVGF, ContactFrame
from svgf_cli.evaluate.plot import pyplot, save_png
from svgf_cli.evaluate.report import EvaluationReport

CELL_INCHES = 3.2


def default_contact_frames(frames: Sequence[int]) -> list[int]:
    """First, middle and last evaluated frame (fewer when there are fewer frames)."""
    if not frames:
        return []
    ordered = sorted(frames)
    return sorted({ordered[0], ordered[len(ordered) // 2], ordered[-1]})


def column_order(report: EvaluationReport, methods: Sequence[str] | None = None) -> list[str]:
    """Input first (noisiest), then svgf, then the others in report order (compared outputs,
    then baselines); only ``methods`` when given."""
    names = [m.name for m in report.methods if methods is None or m.name in methods]
    middle = [n for n in names if n not in (INPUT, SVGF)]
    return ([INPUT] if INPUT in names else []) + ([SVGF] if SVGF in names else []) + middle


def write_contact_sheet(
    report: EvaluationReport,
    contacts: Sequence[ContactFrame],
    path: str | os.PathLike[str],
    *,
    error_map: bool = True,
    dpi: float | None = None,
    methods: Sequence[str] | None = None,
    cell_inches: float = CELL_INCHES,
    title_size: float = 8.0,
) -> None:
    """Write a labelled PNG grid: one row per contact frame (without the FLIP column when
    ``error_map`` is False; only the columns of ``methods`` when given)."""
    if not contacts:
        raise ValueError("no contact frames to draw")
    plt = pyplot()
    names = column_order(report, methods)
    columns = [*names, "reference", *(["FLIP error (svgf)"] if error_map else [])]
    height, width = contacts[0].reference.shape[1:]
    cell_h = cell_inches * height / width
    figure, axes = plt.subplots(
        len(contacts),
        len(columns),
        figsize=(cell_inches * len(columns), (cell_h + 0.5) * len(contacts)),
        squeeze=False,
    )
    try:
        for row, contact in enumerate(contacts):
            for col, name in enumerate(columns):
                ax = axes[row, col]
                ax.set_xticks([])
                ax.set_yticks([])
                if name == "reference":
                    ax.imshow(_hwc(contact.reference), interpolation="nearest")
                    title = f"reference\nframe {contact.frame}"
                elif name.startswith("FLIP"):
                    if contact.error_map is None:
                        ax.imshow(np.zeros((height, width)), cmap="gray", vmin=0, vmax=1)
                        title = "FLIP error: svgf output has NaN"
                    else:
                        ax.imshow(contact.error_map, cmap="magma", vmin=0.0, vmax=1.0)
                        title = "FLIP error map\n(svgf)"
                else:
                    ax.imshow(_hwc(contact.images[name]), interpolation="nearest")
                    title = _cell_title(report, name, contact.frame)
                ax.set_title(title, fontsize=title_size)
                if col == 0:
                    ax.set_ylabel(f"frame {contact.frame}", fontsize=9)
        figure.tight_layout()
        save_png(figure, path, dpi=dpi or max(100.0, min(width / cell_inches, 300.0)))
    finally:
        plt.close(figure)


def _hwc(display: np.ndarray) -> np.ndarray:
    return np.clip(np.moveaxis(display, 0, -1), 0.0, 1.0)


def _cell_title(report: EvaluationReport, name: str, frame: int) -> str:
    score = next(f for f in report.method(name).frames if f.frame == frame)
    if score.flagged:
        return f"{name}: {score.nonfinite_pixels} NaN/Inf px (FLAGGED)"
    relmse = score.values.get("relmse")
    flip = score.values.get("flip")
    return f"{name}\nrelMSE {relmse:.3g} FLIP {flip:.3f}"
