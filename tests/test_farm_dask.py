"""Dask backend: a local 2-worker cluster writes exactly what the local chunked run writes."""

from __future__ import annotations

from pathlib import Path

import pytest
from test_cli_support import outputs, run_cli, write_sequence

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

    # A retried/re-run job is idempotent: with --skip-existing nothing is rewritten.
    stamp = {p.name: p.stat().st_mtime_ns for p in outputs(tmp_path / "dask", "o")}
    (tmp_path / "dask" / "o.0005.exr").unlink()
    code, _, err = run_cli(
        [*common, "-o", tmp_path / "dask" / "o.####.exr", "--workers", "2", "--skip-existing",
         "-q"],
        capsys,
    )
    assert code == 0, err
    again = {p.name: p.read_bytes() for p in outputs(tmp_path / "dask", "o")}
    assert again == local
    for p in outputs(tmp_path / "dask", "o"):
        if p.name != "o.0005.exr":
            assert p.stat().st_mtime_ns == stamp[p.name]
