"""The per-frame error plot: one panel per metric, one line per method (matplotlib, Agg)."""

from __future__ import annotations

import math
import os
from pathlib import Path
from typing import Any

from svgf_cli.errors import SvgfError, UsageError
from svgf_cli.evaluate.metrics import METRICS
from svgf_cli.evaluate.report import EvaluationReport

# Stable colours per method so every plot and sheet reads the same way.
METHOD_COLOURS = {
    "svgf": "#d62728",
    "oidn": "#1f77b4",
    "accumulate": "#2ca02c",
    "atrous": "#9467bd",
    "input": "#7f7f7f",
}


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
                    color=METHOD_COLOURS.get(method.name),
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
