"""File patterns, frame specs and input expansion."""

from __future__ import annotations

from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from test_cli_support import run_cli

from svgf_cli.errors import InputError, UsageError
from svgf_cli.io.patterns import (
    SequencePattern,
    expand_inputs,
    format_frame_spec,
    parse_frame_spec,
)


@pytest.mark.parametrize(
    ("spec", "frames"),
    [
        ("5", [5]),
        ("1001-1005", [1001, 1002, 1003, 1004, 1005]),
        ("1,5,7-9", [1, 5, 7, 8, 9]),
        ("1001-1010x3", [1001, 1004, 1007, 1010]),
        ("1-10:4", [1, 5, 9]),
        ("9,1,5,1", [1, 5, 9]),
        (" 3 - 4 , 1 ", [1, 3, 4]),
        ("0", [0]),
        # what fileseq users expect
        ("-3--1", [-3, -2, -1]),
        ("-2-1", [-2, -1, 0, 1]),
        ("1-10y3", [2, 3, 5, 6, 8, 9]),  # the frames x3 leaves out
        ("10-1", list(range(1, 11))),  # order is irrelevant: frames run in timeline order
    ],
)
def test_parse_frame_spec(spec: str, frames: list[int]) -> None:
    assert parse_frame_spec(spec) == frames


@pytest.mark.parametrize(
    ("spec", "fragment"),
    [
        ("", "empty"),
        ("abc", "'abc'"),
        ("1-,5", "'1-'"),
        ("1-10x0", "'1-10x0'"),
        ("1-10x-2", "'1-10x-2'"),
        ("1.5", "sub-frames"),
        ("1-999999999", "more than 1000000"),
        ("1-1000001", "1000001 frames"),
    ],
)
def test_parse_frame_spec_errors_quote_the_bad_part(spec: str, fragment: str) -> None:
    with pytest.raises(ValueError, match="frame spec") as err:
        parse_frame_spec(spec)
    assert fragment in str(err.value)
    assert "\n" not in str(err.value)


def test_huge_frame_range_is_a_one_line_usage_error(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    _touch(tmp_path, "in.0001.exr")
    args = ["denoise", str(tmp_path / "in.####.exr"), "-o", str(tmp_path / "o.####.exr")]
    code, out, err = run_cli([*args, "--frames", "1-999999999"], capsys)
    assert code == 2
    assert err == "ERROR: --frames: frame spec '1-999999999' names more than 1000000 frames\n"


@settings(max_examples=60, deadline=None)
@given(st.sets(st.integers(min_value=-5000, max_value=5000), min_size=1, max_size=40))
def test_frame_spec_round_trip(frames: set[int]) -> None:
    assert parse_frame_spec(format_frame_spec(frames)) == sorted(frames)


@pytest.mark.parametrize(
    ("text", "frame", "expected"),
    [
        ("in.####.exr", 7, "in.0007.exr"),
        ("in.##.exr", 7, "in.07.exr"),
        ("in.#.exr", 7, "in.0007.exr"),  # fileseq: a lone '#' means 4-padded
        ("in.@.exr", 7, "in.7.exr"),
        ("in.@@@.exr", 7, "in.007.exr"),
        ("in.%04d.exr", 7, "in.0007.exr"),
        ("in.%d.exr", 7, "in.7.exr"),
        ("in.$F4.exr", 7, "in.0007.exr"),
        ("in.$F.exr", 7, "in.7.exr"),
        ("shot.1001.exr", 7, "shot.0007.exr"),  # concrete path: padding from its width
        ("shot_v2_0042.exr", 12345, "shot_v2_12345.exr"),  # last digit group, overflow
        ("dir/beauty.####.exr", 1, "dir/beauty.0001.exr"),
        ("shot_####_v2.exr", 7, "shot_0007_v2.exr"),  # a token mid-name
        ("in.####.exr", -5, "in.-005.exr"),  # the sign counts as a digit (printf, fileseq)
        ("in.@.exr", -5, "in.-5.exr"),
        ("shot.-005.exr", -12, "shot.-012.exr"),  # a signed concrete frame after a dot
        ("plate.0042.jp2", 7, "plate.0007.jp2"),  # a digit in the extension is no frame
    ],
)
def test_pattern_path(text: str, frame: int, expected: str) -> None:
    pattern = SequencePattern.parse(text)
    assert pattern.is_sequence
    assert pattern.path(frame) == Path(expected)
    assert pattern.frame_of(pattern.path(frame)) == frame


def test_plain_file_is_not_a_sequence() -> None:
    pattern = SequencePattern.parse("some/dir/beauty.exr")
    assert not pattern.is_sequence
    assert pattern.path(3) == Path("some/dir/beauty.exr")
    assert pattern.frame_of("some/dir/beauty.exr") is None


def test_a_plain_file_on_disk_is_frame_zero(tmp_path: Path) -> None:
    pattern = SequencePattern.parse(str(tmp_path / "beauty.exr"))
    assert pattern.frames_on_disk() == []
    (tmp_path / "beauty.exr").write_bytes(b"x")
    assert pattern.frames_on_disk() == [0]


@pytest.mark.parametrize("name", ["shot.1001", "x.1001", "a.7"])
def test_digits_only_in_the_extension_make_a_plain_file(name: str) -> None:
    # The extension is never the frame number, whatever the stem's length.
    pattern = SequencePattern.parse(f"dir/{name}")
    assert not pattern.is_sequence
    assert pattern.path(3) == Path(f"dir/{name}")


def test_frame_of_rejects_wrong_padding_and_names() -> None:
    pattern = SequencePattern.parse("in.####.exr")
    assert pattern.frame_of("in.0012.exr") == 12
    assert pattern.frame_of("in.012.exr") is None
    assert pattern.frame_of("in.00012.exr") is None
    assert pattern.frame_of("in.12345.exr") == 12345
    assert pattern.frame_of("out.0012.exr") is None
    assert pattern.frame_of("in.00a2.exr") is None
    assert SequencePattern.parse("in.@.exr").frame_of("in.07.exr") is None


def test_display_uses_hash_form() -> None:
    assert SequencePattern.parse("a/in.%04d.exr").display == "a/in.####.exr"
    assert SequencePattern.parse("in.$F.exr").display == "in.@.exr"


@pytest.mark.parametrize("text", ["in.##.@@.exr", "", "a.####/x.exr"])
def test_bad_patterns(text: str) -> None:
    with pytest.raises(UsageError):
        SequencePattern.parse(text)


def _touch(folder: Path, *names: str) -> None:
    for name in names:
        (folder / name).write_bytes(b"x")


def test_frames_on_disk_scans_and_ignores_dot_files(tmp_path: Path) -> None:
    _touch(
        tmp_path,
        "r.1003.exr",
        "r.1001.exr",
        "r.1002.exr",
        ".r.1004.exr.123.tmp.exr",
        "r.999.exr",  # wrong padding
        "r.1005.exr.bak",
        "other.1006.exr",
    )
    (tmp_path / "r.1007.exr").mkdir()  # a directory is not a frame
    pattern = SequencePattern.parse(str(tmp_path / "r.####.exr"))
    assert pattern.frames_on_disk() == [1001, 1002, 1003]
    assert SequencePattern.parse(str(tmp_path / "missing" / "r.####.exr")).frames_on_disk() == []


def test_expand_single_pattern_and_concrete_path(tmp_path: Path) -> None:
    _touch(tmp_path, "r.0002.exr", "r.0001.exr", "r.0010.exr")
    expected = [(n, tmp_path / f"r.{n:04d}.exr") for n in (1, 2, 10)]
    assert expand_inputs([str(tmp_path / "r.####.exr")]) == expected
    assert expand_inputs([str(tmp_path / "r.%04d.exr")]) == expected
    # noice style: a concrete frame path stands for its whole sequence
    assert expand_inputs([str(tmp_path / "r.0002.exr")]) == expected


def test_expand_plain_file_and_explicit_lists(tmp_path: Path) -> None:
    _touch(tmp_path, "beauty.exr", "a_12.exr", "b_3.exr", "noframe.exr")
    assert expand_inputs([str(tmp_path / "beauty.exr")]) == [(0, tmp_path / "beauty.exr")]
    numbered = expand_inputs([str(tmp_path / "a_12.exr"), str(tmp_path / "b_3.exr")])
    assert numbered == [(3, tmp_path / "b_3.exr"), (12, tmp_path / "a_12.exr")]
    # one name without digits: every file numbered by its position, in the order given
    mixed = expand_inputs([str(tmp_path / "a_12.exr"), str(tmp_path / "noframe.exr")])
    assert mixed == [(0, tmp_path / "a_12.exr"), (1, tmp_path / "noframe.exr")]


def test_expand_errors_name_the_input(tmp_path: Path) -> None:
    pattern = str(tmp_path / "r.####.exr")
    with pytest.raises(InputError, match="no files match") as err:
        expand_inputs([pattern])
    assert pattern in str(err.value)
    with pytest.raises(InputError, match="does not exist"):
        expand_inputs([str(tmp_path / "nope" / "r.####.exr")])
    with pytest.raises(InputError, match="not found"):
        expand_inputs([str(tmp_path / "plain.exr")])
    _touch(tmp_path, "a_1.exr", "b_1.exr")
    with pytest.raises(InputError, match="same frame number 1"):
        expand_inputs([str(tmp_path / "a_1.exr"), str(tmp_path / "b_1.exr")])
    with pytest.raises(InputError, match="not found"):
        expand_inputs([str(tmp_path / "a_1.exr"), str(tmp_path / "c_2.exr")])
    with pytest.raises(UsageError, match="one pattern"):
        expand_inputs([str(tmp_path / "a_1.exr"), pattern])
    with pytest.raises(UsageError):
        expand_inputs([])


def test_negative_frames_on_disk(tmp_path: Path) -> None:
    _touch(tmp_path, "r.-002.exr", "r.-001.exr", "r.0000.exr", "r.0001.exr", "r.-01.exr")
    pattern = SequencePattern.parse(str(tmp_path / "r.####.exr"))
    assert pattern.frames_on_disk() == [-2, -1, 0, 1]  # "-01" is not what #### writes
    assert [f for f, _ in expand_inputs([str(tmp_path / "r.-002.exr")])] == [-2, -1, 0, 1]
