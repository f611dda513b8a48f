"""Dask backend: a local 2-worker cluster writes exactly what the local chunked run writes."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import pytest
from test_cli_support import outputs, run_cli, write_sequence

from svgf_cli.farm.dask_backend import run_chunk_task
from svgf_cli.farm.job import build_job
from svgf_cli.filters.params import DEFAULT_PRESET, PRESETS
from svgf_cli.io.layers import build_mapping
from svgf_cli.run.tasks import RunConfig

pytest.importorskip("distributed")  # the optional `farm` extra (part of `dev`)


def test_two_workers_equal_local_chunked_run(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    write_sequence(tmp_path / "seq", range(1, 9))
    common = ["denoise", tmp_path / "seq" / "in.####.exr", "--chunk-size", "3", "--warmup", "2"]
    code, _, err = run_cli([*common, "-o", tmp_path / "local" / "o.####.exr", "-q"], capsys)
    assert code == 0, err
    code, stdout, err = run_cli(
        [*common, "-o", tmp_path / "dask" / "o.####.exr", "--workers", "2"], capsys
    )
    assert code == 0, err
    assert "Dask: 3 chunk task(s)" in stdout and stdout.count("Progress: ") == 8
    local = {p.name: p.read_bytes() for p in outputs(tmp_path / "local", "o")}
    remote = {p.name: p.read_bytes() for p in outputs(tmp_path / "dask", "o")}
    assert len(local) == 8
    assert remote == local

    # A retried task is idempotent: it keeps the outputs that exist and recomputes only the
    # missing one, with the same warm-up, so the result is the same bytes.
    stamp = {p.name: p.stat().st_mtime_ns for p in outputs(tmp_path / "dask", "o")}
    (tmp_path / "dask" / "o.0005.exr").unlink()
    job = build_job(
        [str(tmp_path / "seq" / "in.####.exr")],
        str(tmp_path / "dask" / "o.####.exr"),
        warmup=2,
        chunk_size=3,
        skip_existing=True,
    )
    assert [t.frame for t in job.chunk_tasks[0]] == [3, 4, 5]  # re-planned around the hole
    original = build_job(
        [str(tmp_path / "seq" / "in.####.exr")],
        str(tmp_path / "x" / "o.####.exr"),
        warmup=2,
        chunk_size=3,
        warm_start=PRESETS[DEFAULT_PRESET].warm_start,  # as `svgf denoise` plans it
    )
    retry = [
        replace(t, output=tmp_path / "dask" / t.output.name if t.output else None)
        for t in original.chunk_tasks[1]
    ]
    config = RunConfig(
        params=PRESETS[DEFAULT_PRESET], preset=DEFAULT_PRESET, mapping=build_mapping(),
        warmup_label="2",
    )
    summary = run_chunk_task(retry, config, overwrite=False)
    assert summary["written"] == [5]
    again = {p.name: p.read_bytes() for p in outputs(tmp_path / "dask", "o")}
    assert again == local
    for p in outputs(tmp_path / "dask", "o"):
        if p.name != "o.0005.exr":
            assert p.stat().st_mtime_ns == stamp[p.name]
