"""The per-frame error plot: one panel per metric, one line per method (matplotlib, Agg)."""

from __future__ import annotations

import math
import os
import zlib
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from svgf_cli.errors import SvgfError, UsageError
from svgf_cli.evaluate.metrics import METRIC_INFO, METRICS
from svgf_cli.evaluate.report import EvaluationReport

# Stable colours per method so every plot and sheet reads the same way.
METHOD_COLOURS = {
    "svgf": "#d62728",
    "oidn": "#1f77b4",
    "accumulate": "#2ca02c",
    "atrous": "#9467bd",
    "input": "#7f7f7f",
    "svgf-paper": "#ff7f0e",
    "svgf-no-temporal": "#8c564b",
    "svgf-bidirectional": "#000000",
    "svgf-lobes": "#e377c2",
    "svgf-combined": "#17becf",
}
# In-memory baselines are dashed and the raw input dotted, so the denoised methods (solid)
# stand out and a baseline that coincides with one of them stays visible.
METHOD_STYLES = {"oidn": "--", "accumulate": "--", "atrous": "--", "input": ":"}
# Other methods (e.g. compared svgf variants) get one of these, chosen from the name so a
# method keeps its colour in every plot.
EXTRA_COLOURS = ("#bcbd22", "#1a55ff", "#9edae5", "#ff9896", "#c5b0d5", "#98df8a")


def method_colour(name: str) -> str:
    """The method's colour: fixed for the known methods, else picked by a hash of the name."""
    if name in METHOD_COLOURS:
        return METHOD_COLOURS[name]
    return EXTRA_COLOURS[zlib.crc32(name.encode()) % len(EXTRA_COLOURS)]


def pyplot() -> Any:
    """matplotlib.pyplot on the Agg backend (no display needed), or a clear UsageError."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError as exc:
        raise UsageError(
            "--plot and --contact-sheet need matplotlib: pip install matplotlib"
        ) from exc
    return plt


def save_png(figure: Any, path: str | os.PathLike[str], dpi: float) -> None:
    """Write ``figure`` as PNG atomically (hidden temporary sibling, then rename)."""
    target = Path(path)
    if target.parent and not target.parent.is_dir():
        raise SvgfError(f"directory {target.parent} does not exist", str(target))
    tmp = target.with_name(f".{target.name}.{os.getpid()}.tmp.png")
    try:
        # No Software/date metadata: the same report gives the same bytes.
        figure.savefig(tmp, format="png", dpi=dpi, metadata={"Software": None})
        os.replace(tmp, target)
    except OSError as exc:
        raise SvgfError(f"cannot write PNG: {exc.strerror or exc}", str(target)) from exc
    finally:
        tmp.unlink(missing_ok=True)


def write_plot(report: EvaluationReport, path: str | os.PathLike[str]) -> None:
    """Per-frame RMSE, relMSE, PSNR, SSIM, FLIP and temporal error of every method.

    Error metrics use a log scale when all their values are positive. Flagged frames (NaN
    output) appear as gaps and are named in the panel's legend.
    """
    plt = pyplot()
    columns = 3
    rows = math.ceil(len(METRICS) / columns)
    figure, axes = plt.subplots(rows, columns, figsize=(5.0 * columns, 3.4 * rows), squeeze=False)
    try:
        for ax, info in zip(axes.ravel(), METRICS, strict=False):
            positive = True
            for method in report.methods:
                xs = [f.frame for f in method.frames]
                ys = [_plottable(f.values.get(info.key)) for f in method.frames]
                positive &= all(y > 0 for y in ys if not math.isnan(y))
                label = method.name + (" (NaN frames)" if method.flagged else "")
                ax.plot(
                    xs,
                    ys,
                    marker="o",
                    markersize=3,
                    linewidth=1.4,
                    label=label,
                    color=method_colour(method.name),
                )
            arrow = "higher is better" if info.higher_is_better else "lower is better"
            unit = f" [{info.unit}]" if info.unit else ""
            ax.set_title(f"{info.label}{unit} ({arrow})", fontsize=10)
            ax.set_xlabel("frame")
            if positive and not info.higher_is_better:
                ax.set_yscale("log")
            ax.grid(True, alpha=0.3)
            ax.xaxis.get_major_locator().set_params(integer=True)
        for ax in axes.ravel()[len(METRICS) :]:
            ax.set_visible(False)
        axes.ravel()[0].legend(fontsize=8)
        figure.suptitle(f"Per-frame error vs reference {report.inputs.get('reference')}")
        figure.tight_layout()
        save_png(figure, path, dpi=100)
    finally:
        plt.close(figure)


def _plottable(value: float | None) -> float:
    """None (undefined) and +inf (identical images) are not drawable: both become gaps."""
    if value is None or math.isinf(value):
        return math.nan
    return value


def write_curves(
    report: EvaluationReport,
    path: str | os.PathLike[str],
    keys: Sequence[str],
    *,
    marks: Mapping[int, str] | None = None,
    title: str = "",
    dpi: float = 80.0,
) -> None:
    """A compact per-frame plot: one panel per metric in ``keys``, one line per method, a
    dashed vertical line at each frame of ``marks`` (e.g. a light change), labelled in the
    first panel. Error metrics use a log scale when all their values are positive."""
    plt = pyplot()
    figure, axes = plt.subplots(1, len(keys), figsize=(4.2 * len(keys), 3.3), squeeze=False)
    try:
        for index, (ax, key) in enumerate(zip(axes[0], keys, strict=True)):
            info = METRIC_INFO[key]
            positive = True
            for method in report.methods:
                xs = [f.frame for f in method.frames]
                ys = [_plottable(f.values.get(key)) for f in method.frames]
                positive &= all(y > 0 for y in ys if not math.isnan(y))
                ax.plot(
                    xs, ys, marker="o", markersize=2.5, linewidth=1.2,
                    linestyle=METHOD_STYLES.get(method.name, "-"),
                    label=method.name, color=method_colour(method.name),
                )
            for frame, text in sorted((marks or {}).items()):
                ax.axvline(frame, color="#444444", linestyle="--", linewidth=0.8)
                if index == 0:
                    ax.annotate(
                        text, (frame, 1.0), xycoords=("data", "axes fraction"),
                        xytext=(2, -10), textcoords="offset points", fontsize=7,
                    )
            arrow = "higher is better" if info.higher_is_better else "lower is better"
            ax.set_title(f"{info.label} ({arrow})", fontsize=9)
            ax.set_xlabel("frame", fontsize=8)
            ax.tick_params(labelsize=7)
            if positive and not info.higher_is_better:
                ax.set_yscale("log")
            ax.grid(True, alpha=0.3)
            ax.xaxis.get_major_locator().set_params(integer=True)
        handles, labels = axes[0, 0].get_legend_handles_labels()
        figure.legend(handles, labels, loc="center right", fontsize=7, frameon=False)
        if title:
            figure.suptitle(title, fontsize=10)
        # Leave the right edge to the legend (about 1.6 inches).
        width = figure.get_size_inches()[0]
        figure.tight_layout(rect=(0.0, 0.0, 1.0 - 1.6 / width, 1.0))
        save_png(figure, path, dpi=dpi)
    finally:
        plt.close(figure)
