"""The OpenJD job template, run by `openjd run`, and the Deadline submission files.

The template's chunks must write exactly the bytes of a local chunked run with the same
chunks and warm-up. (OpenJD balances chunk lengths, 10 frames by 4 giving 4, 3, 3, where the
local plan gives 4, 4, 2; 10 frames by 5 are the same chunks in both.)
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
from test_cli_support import REPO, run_cli

from svgf_cli.farm.submit import OPENJD_TEMPLATE

pytest.importorskip("openjd.cli", reason="openjd-cli is in the dev extra")
BIN = Path(sys.executable).parent
SEQUENCE = REPO / "testdata" / "seq" / "in.####.exr"


def test_openjd_template_matches_a_local_chunked_run(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    farm_out = tmp_path / "farm" / "den.####.exr"
    code, out, err = run_cli(
        ["plan", "--frames", "1-10", "--chunk-size", "5", "--warmup", "3", "--format", "openjd",
         "--executable", BIN / "svgf", "--", SEQUENCE, "-o", farm_out],
        capsys,
    )  # fmt: skip
    assert code == 0, err
    params = json.loads(out)
    assert params["Frames"] == "1-10" and params["ChunkSize"] == 5 and params["Warmup"] == "3"
    params_file = tmp_path / "params.json"
    params_file.write_text(out)
    run = subprocess.run(
        [BIN / "openjd", "run", REPO / OPENJD_TEMPLATE, "-p", f"file://{params_file}"],
        capture_output=True, text=True, cwd=tmp_path, timeout=300,
    )  # fmt: skip
    assert run.returncode == 0, run.stdout[-3000:] + run.stderr[-3000:]
    assert "Chunks run: 2" in run.stdout  # 1-5, 6-10
    assert "Warmup: 3/3 (frame 5)" in run.stdout  # chunk 6-10 replayed 3-5

    local_out = tmp_path / "local" / "den.####.exr"
    code, _, err = run_cli(
        ["denoise", SEQUENCE, "-o", local_out, "--chunk-size", "5", "--warmup", "3", "-q"], capsys
    )
    assert code == 0, err
    farm = sorted((tmp_path / "farm").glob("den.*.exr"))
    local = sorted((tmp_path / "local").glob("den.*.exr"))
    assert [p.name for p in farm] == [p.name for p in local] and len(farm) == 10
    for a, b in zip(farm, local, strict=True):
        assert a.read_bytes() == b.read_bytes(), a.name


def test_openjd_parameters_refuse_options_the_template_lacks(
    capsys: pytest.CaptureFixture[str],
) -> None:
    code, _, err = run_cli(
        ["plan", "--frames", "1-10", "--chunk-size", "4", "--format", "openjd", "--",
         "in.####.exr", "-o", "o.####.exr", "--float"],
        capsys,
    )  # fmt: skip
    assert code == 2 and "no job parameter for --float" in err


def test_openjd_frames_use_its_step_syntax(capsys: pytest.CaptureFixture[str]) -> None:
    code, out, err = run_cli(
        ["plan", "--frames", "1-9x2", "--chunk-size", "2", "--format", "openjd", "--",
         "in.####.exr", "-o", "o.####.exr"],
        capsys,
    )  # fmt: skip
    assert code == 0, err
    assert json.loads(out)["Frames"] == "1-9:2"


def test_deadline_submission_files(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    code, out, err = run_cli(
        ["plan", "--frames", "1001-1100", "--chunk-size", "25", "--format", "deadline",
         "--out", tmp_path, "--", "sh 10/in.%04d.exr", "-o", "den/out.%04d.exr", "--float"],
        capsys,
    )  # fmt: skip
    assert code == 0, err
    job = (tmp_path / "svgf_job_info.job").read_text().splitlines()
    plugin = (tmp_path / "svgf_plugin_info.job").read_text().splitlines()
    assert out.strip().startswith("deadlinecommand ") and str(tmp_path) in out
    assert {"Plugin=CommandLine", "Frames=1001-1100", "ChunkSize=25"} <= set(job)
    assert "OutputFilename0=den/out.####.exr" in job
    assert "Executable=svgf" in plugin
    assert (
        "Arguments=denoise <QUOTE>sh 10/in.%04d.exr<QUOTE> -o den/out.%04d.exr --float "
        "--frames <STARTFRAME>-<ENDFRAME> --warmup 16 --skip-existing"
    ) in plugin
    code, _, err = run_cli(
        ["plan", "--frames", "1-9x2", "--chunk-size", "2", "--format", "deadline", "--out",
         tmp_path, "--", "in.####.exr", "-o", "o.####.exr"],
        capsys,
    )  # fmt: skip
    assert code == 2 and "contiguous" in err
