"""The stages a run applies are named: in the ``-v`` start-up log and as ``svgf/stages`` in
each output (``svgf_cli.run.stages``; the names come from the filter's pipeline). Stand-in
stage names here: the driver's part is only to report what the pipeline says."""

from __future__ import annotations

import dataclasses
import io
from pathlib import Path

import pytest

from svgf_cli.filters.params import SVGFParams
from svgf_cli.progress import Progress
from svgf_cli.run import stages
from svgf_cli.run.chunk import run_sequence
from svgf_cli.run.output import output_attributes
from svgf_cli.run.tasks import FrameTask, RunConfig


def _named(params: SVGFParams, kind: str) -> list[str]:
    return [f"{kind}-a", f"{kind}-b"]


def _config(bidirectional: bool) -> RunConfig:
    params = dataclasses.replace(SVGFParams(), bidirectional=bidirectional)
    return RunConfig(params=params, preset="paper", mapping=None)  # type: ignore[arg-type]


@pytest.mark.parametrize(("bidirectional", "expected"), [
    (False, "causal-a,causal-b"),
    (True, "forward:forward-a,forward:forward-b,reverse:reverse-a,reverse:reverse-b"),
])
def test_outputs_name_the_stages_and_keep_their_params(
    monkeypatch: pytest.MonkeyPatch, bidirectional: bool, expected: str,
) -> None:
    config = _config(bidirectional)
    task = FrameTask(3, Path("in.0003.exr"), Path("o.0003.exr"))
    monkeypatch.setattr(stages, "stage_names", _named)
    attributes = output_attributes(config, task)
    assert attributes["svgf/stages"] == expected
    assert attributes["svgf/params"] == config.params.to_json()


def test_no_stage_named_writes_no_stages_attribute(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(stages, "stage_names", lambda params, kind: [])
    task = FrameTask(3, Path("in.0003.exr"), Path("o.0003.exr"))
    assert "svgf/stages" not in output_attributes(_config(False), task)


@pytest.mark.parametrize(("bidirectional", "lines"), [
    (False, ["causal stages: causal-a, causal-b"]),
    (True, ["forward stages: forward-a, forward-b", "reverse stages: reverse-a, reverse-b"]),
])
def test_a_run_logs_its_stages_at_detail_level(
    monkeypatch: pytest.MonkeyPatch, bidirectional: bool, lines: list[str],
) -> None:
    monkeypatch.setattr(stages, "stage_names", _named)
    for verbose in (False, True):
        out = io.StringIO()
        progress = Progress("lines", 0, verbose=verbose, out=out, err=io.StringIO())
        run_sequence([], _config(bidirectional), progress)  # no frame: only the log
        assert out.getvalue().splitlines() == (lines if verbose else [])
