"""The runner's output side: what it writes for a frame and what it reports.

The Denoiser's own counts (``DenoisedFrame.warnings()``) become ``WARNING:`` lines; the
output value policy (non-finite -> 0, half clamped) is counted; the layout follows the
input (`build_output`).
"""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np
from exr_fixtures import PartSpec, gbuffer, read_parts, write_parts

from svgf_cli.filters.params import SVGFParams
from svgf_cli.frame import DenoisedFrame
from svgf_cli.io.exr import read_frame
from svgf_cli.io.layers import build_mapping
from svgf_cli.progress import Progress
from svgf_cli.run.chunk import run_sequence
from svgf_cli.run.output import build_output
from svgf_cli.run.tasks import FrameTask, RunConfig


class CountingDenoiser:
    """Passes the colour through and reports what a value policy would have counted."""

    def __init__(self, params: SVGFParams, debug: bool) -> None:
        self.frames_processed = 0

    def process(self, frame) -> DenoisedFrame:
        self.frames_processed += 1
        colour = frame.total_radiance()
        colour[0, 0, 0] = np.nan  # to be caught by the output boundary
        colour[1, 0, 1] = 1e6  # beyond half
        counts = {"nonfinite": 0, "extreme": 3, "extreme.radiance.direct": 3,
                  "history_resets": 0}
        return DenoisedFrame(color=colour, layers={}, counts=counts)

    def reset(self) -> None: ...

    def state(self) -> dict:
        return {}

    def load_state(self, state: dict) -> None: ...


def test_denoiser_counts_and_output_policy_become_warnings(tmp_path: Path) -> None:
    channels = dict(gbuffer())
    for c in "RGB":
        channels[c] = channels[c].astype(np.float16)
    path = write_parts(tmp_path / "in.0001.exr", [PartSpec(channels)])
    err = io.StringIO()
    progress = Progress("lines", 1, quiet=True, out=io.StringIO(), err=err)
    task = FrameTask(1, path, tmp_path / "o.0001.exr")
    config = RunConfig(params=SVGFParams(), preset="paper", mapping=build_mapping())
    run_sequence([task], config, progress, make_denoiser=CountingDenoiser)
    # A library caller's default output is the drop-in one: every input channel is kept.
    (_, _, written), = read_parts(tmp_path / "o.0001.exr")
    assert set(channels) <= set(written)
    lines = err.getvalue().splitlines()
    assert (f"WARNING: {path}: 3 input value(s) beyond +-1e15 replaced by 0"
            " (radiance.direct 3)" in lines)
    assert f"WARNING: {path}: 1 non-finite output value(s) set to 0" in lines
    assert (
        f"WARNING: {path}: 1 output value(s) beyond the half-float range clamped to +-65504 "
        "(--float keeps them)" in lines
    )


def test_build_output_layout(tmp_path: Path) -> None:
    data = gbuffer()
    beauty = {f"view.beauty.{c}": data.pop(c) for c in "RGB"}
    beauty["view.beauty.A"] = np.full_like(beauty["view.beauty.R"], 0.5)
    path = write_parts(tmp_path / "in.0001.exr", [PartSpec(data, "data"),
                                                   PartSpec(beauty, "beauty")])
    mapping = build_mapping("svgf", ["color=beauty", "alpha=beauty.A"])
    result = read_frame(path, mapping)
    assert result.colour_channels == tuple(f"view.beauty.{c}" for c in "RGB")
    denoised = DenoisedFrame(color=np.ones((3, 8, 12), np.float32),
                             layers={"history_length.color": np.zeros((8, 12), np.float32)})
    task = FrameTask(1, path, tmp_path / "o.exr")
    config = RunConfig(params=SVGFParams(), preset="paper", mapping=mapping, debug_aovs=True,
                       colour_only=True)
    output = build_output(result, denoised, config, task)
    assert output.part_index == 1  # the colour's own part
    assert set(output.channels) == {"view.beauty.R", "view.beauty.G", "view.beauty.B",
                                    "svgf.history_length.color"}
    assert output.keep_only == {"view.beauty.A"}
    assert output.channels["view.beauty.R"].dtype == np.float32  # the input's type
    assert output.attributes["svgf/kind"] == "denoised"


def test_a_stand_in_reader_s_alpha_is_written(tmp_path: Path) -> None:
    """A reader that decoded no file (a library caller's stand-in) still gets its alpha
    written next to the colour, not dropped or replaced by 1."""
    from types import SimpleNamespace

    alpha = np.linspace(0.0, 0.9, 6 * 4, dtype=np.float32).reshape(4, 6)
    result = SimpleNamespace(info=SimpleNamespace(attributes={}, compression="zip"),
                             alpha=alpha, source=None, colour_channels=None, resolved=None)
    denoised = DenoisedFrame(color=np.ones((3, 4, 6), np.float32), layers={}, counts={})
    task = FrameTask(1, tmp_path / "in.0001.exr", tmp_path / "o.0001.exr")
    config = RunConfig(params=SVGFParams(), preset="paper", mapping=build_mapping())
    output = build_output(result, denoised, config, task)
    part = output.source.parts[output.part_index]
    assert set(output.channels) == {"R", "G", "B"}
    np.testing.assert_array_equal(part.channels["A"].pixels, alpha)
