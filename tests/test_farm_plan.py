"""Chunk plans and `svgf plan`."""

from __future__ import annotations

import json
import shlex

import pytest
from hypothesis import given
from hypothesis import strategies as st
from test_cli_support import run_cli

from svgf_cli.farm.plan import plan_chunks
from svgf_cli.io.patterns import format_frame_spec, parse_frame_spec


def test_chunks_cover_every_frame_once_with_clamped_warmup() -> None:
    timeline = list(range(1001, 1101))
    chunks = plan_chunks(range(1001, 1101), timeline, chunk_size=25, warmup=16)
    assert [(c.read_start, c.read_end, c.write_start, c.write_end) for c in chunks] == [
        (1001, 1025, 1001, 1025),
        (1010, 1050, 1026, 1050),
        (1035, 1075, 1051, 1075),
        (1060, 1100, 1076, 1100),
    ]
    written = [f for c in chunks for f in c.write]
    assert written == timeline


def test_warmup_all_reads_from_the_sequence_start() -> None:
    chunks = plan_chunks([5, 6, 7, 8], list(range(1, 9)), chunk_size=2, warmup=None)
    assert [(c.read_start, c.read_end) for c in chunks] == [(1, 6), (1, 8)]


def test_warmup_counts_timeline_frames_not_numbers() -> None:
    # A sequence with a hole: warm-up 2 before frame 10 is frames 7 and 8 (9 is absent).
    chunks = plan_chunks([10], [5, 6, 7, 8, 10], chunk_size=None, warmup=2)
    assert (chunks[0].read_start, chunks[0].read_end) == (7, 10)


def test_plan_refuses_frames_outside_the_timeline() -> None:
    with pytest.raises(ValueError, match="frame 99"):
        plan_chunks([1, 99], [1, 2, 3], chunk_size=None, warmup=0)


@given(st.sets(st.integers(0, 300), min_size=1, max_size=60))
def test_frame_spec_round_trips(frames: set[int]) -> None:
    assert parse_frame_spec(format_frame_spec(sorted(frames))) == sorted(frames)


def test_frame_spec_is_compact() -> None:
    assert format_frame_spec([1, 2, 3, 4]) == "1-4"
    assert format_frame_spec([1, 3, 5, 7]) == "1-7x2"
    assert format_frame_spec([1, 5, 7, 8, 9]) == "1,5,7-9"


def test_plan_json(capsys: pytest.CaptureFixture[str]) -> None:
    code, out, err = run_cli(
        ["plan", "--frames", "1001-1100", "--chunk-size", "25", "--warmup", "16"], capsys
    )
    assert code == 0, err
    plan = json.loads(out)
    assert plan[0] == {
        "chunk": 0,
        "read": [1001, 1025],
        "write": [1001, 1025],
        "frames": "1001-1025",
    }
    assert plan[3] == {
        "chunk": 3,
        "read": [1060, 1100],
        "write": [1076, 1100],
        "frames": "1076-1100",
    }


def test_plan_commands(capsys: pytest.CaptureFixture[str]) -> None:
    code, out, err = run_cli(
        [
            "plan",
            "--frames",
            "1-10",
            "--chunk-size",
            "4",
            "--warmup",
            "3",
            "--format",
            "commands",
            "--",
            "shots/in.####.exr",
            "-o",
            "den dir/out.####.exr",
            "--float",
        ],
        capsys,
    )
    assert code == 0, err
    lines = out.strip().splitlines()
    assert len(lines) == 3
    words = shlex.split(lines[1])
    assert words[:6] == [
        "svgf",
        "denoise",
        "shots/in.####.exr",
        "-o",
        "den dir/out.####.exr",
        "--float",
    ]
    assert words[6:] == ["--frames", "5-8", "--warmup", "3"]


def test_plan_refuses_planned_options_in_passthrough(capsys: pytest.CaptureFixture[str]) -> None:
    code, _, err = run_cli(
        ["plan", "--frames", "1-10", "--chunk-size", "4", "--", "in.####.exr", "--frames", "3"],
        capsys,
    )
    assert code == 2
    assert err.startswith("ERROR: --frames is set by the plan")


def test_plan_bad_spec_is_usage_error(capsys: pytest.CaptureFixture[str]) -> None:
    code, _, err = run_cli(["plan", "--frames", "1-10x0", "--chunk-size", "4"], capsys)
    assert code == 2
    assert "ERROR: --frames" in err and "'1-10x0'" in err
