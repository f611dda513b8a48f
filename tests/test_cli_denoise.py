"""`svgf denoise` end to end on tiny synthetic EXR sequences (in-process)."""

from __future__ import annotations

import json
import re
import shutil
from pathlib import Path

import numpy as np
import OpenEXR
import pytest
from exr_fixtures import ExrImage, read_exr
from test_cli_support import (
    INPUT_ATTRIBUTES,
    frame_channels,
    outputs,
    reference_run,
    run_cli,
    sequence_folder,
    write_sequence,
)

from svgf_cli.filters.params import DEFAULT_PRESET, PRESETS
from svgf_cli.io.exr import write_exr

FRAMES = range(1, 9)


@pytest.fixture(scope="module")
def sequence(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return sequence_folder(tmp_path_factory, FRAMES)


@pytest.fixture(scope="module")
def reference(sequence: Path, tmp_path_factory: pytest.TempPathFactory) -> dict[int, ExrImage]:
    """The full sequential run: frame -> its output."""
    return {f: read_exr(p) for f, p in reference_run(tmp_path_factory, sequence).items()}


@pytest.mark.parametrize("flag", ["--low-memory", "--keep-memory"])
def test_memory_options_say_so_and_write_the_same_frames(
    flag: str,
    sequence: Path,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    reference: dict[int, ExrImage],
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """--low-memory changes when frames are read and --keep-memory where freed memory goes
    (the runner sets glibc's keeping policy: recorded here, so this test process keeps its
    own), not what is written: the start-up log says it, every output is the default
    run's, bit for bit; a plain run logs neither and sets no policy."""
    import svgf_cli.run.chunk as chunk

    calls: list[bool] = []
    monkeypatch.setattr(chunk, "keep_freed_blocks", lambda: calls.append(True) or True)
    out = tmp_path / "den"
    code, stdout, err = run_cli(
        ["denoise", sequence / "in.####.exr", "-o", out / "den.####.exr", flag], capsys)
    assert code == 0, err
    assert f"Memory: {flag}" in stdout
    assert bool(calls) == (flag == "--keep-memory")
    files = outputs(out, "den")
    assert len(files) == len(FRAMES)
    for frame, path in zip(FRAMES, files, strict=True):
        assert read_exr(path).same_pixels(reference[frame]), frame
    calls.clear()
    code, stdout, _ = run_cli(["denoise", sequence / "in.####.exr", "-o",
                               tmp_path / "plain" / "den.####.exr"], capsys)
    assert code == 0 and "Memory:" not in stdout and not calls


def copy_inputs(sequence: Path, dest: Path) -> Path:
    shutil.copytree(sequence, dest)
    return dest


def test_end_to_end_outputs_and_metadata(
    sequence: Path,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    reference: dict[int, ExrImage],
) -> None:
    out = tmp_path / "den"
    code, stdout, err = run_cli(
        ["denoise", sequence / "in.####.exr", "-o", out / "den.####.exr"], capsys
    )
    assert code == 0, err
    files = outputs(out, "den")
    assert [p.name for p in files] == [f"den.{f:04d}.exr" for f in FRAMES]
    image = read_exr(files[3])
    source = read_exr(sequence / "in.0004.exr")
    # A drop-in replacement: every input channel as read. The input has no colour layer
    # (direct + indirect only), so the denoised colour is added as R,G,B (half).
    assert "R" not in source.channels
    assert sorted(image.channels) == sorted([*source.channels, "R", "G", "B"])
    for name, plane in image.channels.items():
        if name in "RGB":
            assert plane.dtype == np.float16
            continue
        assert plane.dtype == source.channels[name].dtype, name
        assert np.array_equal(plane, source.channels[name]), name
    rgb = image.rgb()
    assert np.isfinite(rgb).all() and rgb.mean() > 0
    header = image.header
    params = json.loads(header["svgf/params"])
    assert params == json.loads(PRESETS[DEFAULT_PRESET].to_json())
    assert header["svgf/preset"] == DEFAULT_PRESET == "default"
    assert header["svgf/frame"] == 4
    assert header["svgf/input"].endswith("in.0004.exr")
    assert header["svgf/warmup"] == "all"
    for key, value in INPUT_ATTRIBUTES.items():
        assert header[key] == value
    # Start-up log: version, threads, preset + params, resolved layers; then one line a frame.
    assert "svgf 0.1.0" in stdout and "Threads:" in stdout and "Preset: default" in stdout
    assert "direct: direct.R, direct.G, direct.B" in stdout
    assert stdout.count("Progress: ") == len(FRAMES)
    assert "Progress: 50% (frame 4, 4/8," in stdout
    # Two runs are bit-identical (the fixture ran the same thing).
    assert image.same_pixels(reference[4])


def test_float_output_and_debug_aovs(
    sequence: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    code, _, err = run_cli(
        [
            "denoise",
            sequence / "in.####.exr",
            "-o",
            tmp_path / "o.####.exr",
            "--frames",
            "1-2",
            "--float",
            "--debug-aovs",
            "-q",
        ],
        capsys,
    )
    assert code == 0, err
    channels = read_exr(tmp_path / "o.0002.exr").channels
    debug = [n for n in channels if n.startswith("svgf.")]
    assert {"svgf.history_length.direct", "svgf.variance.direct", "svgf.direct.R",
            "svgf.radiance_mode.indirect"} <= set(debug)
    assert all(plane.dtype == np.float32 for plane in channels.values())


def test_output_equal_to_input_is_refused(
    sequence: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    seq = copy_inputs(sequence, tmp_path / "seq")
    before = (seq / "in.0001.exr").read_bytes()
    code, _, err = run_cli(["denoise", seq / "in.####.exr", "-o", seq / "in.%04d.exr"], capsys)
    assert code == 2
    assert err.startswith("ERROR: ") and "in.0001.exr" in err and "input" in err
    assert (seq / "in.0001.exr").read_bytes() == before
    # A directory output that is the input directory maps to the same names: refused too.
    code, _, _ = run_cli(["denoise", seq / "in.####.exr", "-o", seq], capsys)
    assert code == 2


def test_existing_output_overwrite_and_skip(
    sequence: Path,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    reference: dict[int, ExrImage],
) -> None:
    out = tmp_path / "out"
    out.mkdir()
    existing = out / "out.0003.exr"
    existing.write_bytes(b"placeholder")
    args = ["denoise", sequence / "in.####.exr", "-o", out / "out.####.exr", "-q"]
    code, _, err = run_cli(args, capsys)
    assert code == 4
    assert (
        err == f"ERROR: {existing}: output exists (1 of 8 outputs exist; use --overwrite or "
        "--skip-existing)\n"
    )
    assert outputs(out) == [existing]  # nothing written

    code, _, err = run_cli([*args, "--skip-existing"], capsys)
    assert code == 0, err
    assert existing.read_bytes() == b"placeholder"  # not rewritten
    for f in (1, 2, 4, 8):  # frames after the skipped one still see the full history
        assert read_exr(out / f"out.{f:04d}.exr").same_pixels(reference[f])

    code, _, err = run_cli([*args, "--overwrite"], capsys)
    assert code == 0, err
    assert read_exr(existing).same_pixels(reference[3])

    code, stdout, _ = run_cli(
        ["denoise", sequence / "in.####.exr", "-o", out / "out.####.exr", "--skip-existing"],
        capsys,
    )
    assert code == 0 and "Nothing to do" in stdout


def test_missing_input_and_missing_frames(
    sequence: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    code, _, err = run_cli(["denoise", tmp_path / "nope.####.exr", "-o", tmp_path / "o"], capsys)
    assert code == 3 and err.startswith("ERROR: ") and "nope.####.exr" in err

    seq = copy_inputs(sequence, tmp_path / "seq")
    (seq / "in.0005.exr").unlink()
    out = tmp_path / "out"
    code, _, err = run_cli(["denoise", seq / "in.####.exr", "-o", out / "o.####.exr"], capsys)
    assert code == 3
    assert "in.0005.exr: frame 5 is missing on disk" in err
    assert not out.exists() or outputs(out, "o") == []  # detected before anything is written

    code, _, err = run_cli(
        ["denoise", seq / "in.####.exr", "-o", out / "o.####.exr", "--frames", "9-10"], capsys
    )
    assert code == 3 and "requested frame 9 not found" in err

    code, _, err = run_cli(
        ["denoise", seq / "in.####.exr", "-o", out / "o.####.exr", "--allow-gaps", "-q"], capsys
    )
    assert code == 0, err
    assert "WARNING: frame(s) 5 missing on disk: history reset at frame 6" in err
    assert [p.name for p in outputs(out, "o")] == [f"o.{f:04d}.exr" for f in FRAMES if f != 5]


def test_missing_channel_names_file_and_channel(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    channels = frame_channels(1)
    del channels["N.Y"]
    write_exr(tmp_path / "in.0001.exr", channels)
    code, _, err = run_cli(["denoise", tmp_path / "in.0001.exr", "-o", tmp_path / "o.exr"], capsys)
    assert code == 3
    line = err.strip()
    assert "\n" not in line and line.startswith(f"ERROR: {tmp_path / 'in.0001.exr'}")
    assert "normal" in line and "N.Y" in line
    assert not (tmp_path / "o.exr").exists()


def test_resolution_change_mid_sequence(
    sequence: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    seq = copy_inputs(sequence, tmp_path / "seq")
    write_exr(seq / "in.0004.exr", frame_channels(4, width=40, height=24))
    out = tmp_path / "out"
    code, _, err = run_cli(["denoise", seq / "in.####.exr", "-o", out / "o.####.exr", "-q"], capsys)
    assert code == 3
    assert "in.0004.exr" in err and "32x24" in err and "40x24" in err
    assert [p.name for p in outputs(out, "o")] == ["o.0001.exr", "o.0002.exr", "o.0003.exr"]


def test_corrupt_file(sequence: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    seq = copy_inputs(sequence, tmp_path / "seq")
    data = (seq / "in.0003.exr").read_bytes()
    (seq / "in.0003.exr").write_bytes(data[: len(data) // 2])
    out = tmp_path / "out"
    code, _, err = run_cli(["denoise", seq / "in.####.exr", "-o", out / "o.####.exr", "-q"], capsys)
    assert code == 3
    assert err.startswith(f"ERROR: {seq / 'in.0003.exr'}:") and err.count("\n") == 1
    assert [p.name for p in outputs(out, "o")] == ["o.0001.exr", "o.0002.exr"]
    assert not [p for p in out.iterdir() if p.name.startswith(".")]  # no temp left


def test_nan_input_warns_and_output_is_finite(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    for f in (1, 2):
        channels = frame_channels(f)
        channels["direct.G"][3:6, 4:9] = np.nan
        channels["indirect.R"][0, 0] = np.inf
        write_exr(tmp_path / f"in.{f:04d}.exr", channels)
    code, _, err = run_cli(
        ["denoise", tmp_path / "in.####.exr", "-o", tmp_path / "o.####.exr", "-q"], capsys
    )
    assert code == 0, err
    assert "WARNING: " in err and "NaN" in err and "in.0001.exr" in err
    for f in (1, 2):
        image = read_exr(tmp_path / f"o.{f:04d}.exr")
        assert np.isfinite(image.rgb()).all()
        # Passed-through layers are the input's, bad values included (documented policy).
        assert np.isnan(image.channels["direct.G"][3:6, 4:9]).all()


def test_frames_selection_and_warmup(
    sequence: Path,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    reference: dict[int, ExrImage],
) -> None:
    out = tmp_path / "all"
    code, stdout, err = run_cli(
        [
            "denoise",
            sequence / "in.####.exr",
            "-o",
            out / "o.####.exr",
            "--frames",
            "5-8x3,6",
            "--warmup",
            "all",
        ],
        capsys,
    )
    assert code == 0, err
    assert [p.name for p in outputs(out, "o")] == ["o.0005.exr", "o.0006.exr", "o.0008.exr"]
    assert "Warmup: 4/5 (frame 4)" in stdout  # frames 1-4 and 7 are history-only
    for f in (5, 6, 8):  # --warmup all reproduces the sequential run bit for bit
        assert read_exr(out / f"o.{f:04d}.exr").same_pixels(reference[f])

    cold = tmp_path / "cold"
    code, _, err = run_cli(
        [
            "denoise",
            sequence / "in.####.exr",
            "-o",
            cold / "o.####.exr",
            "--frames",
            "8",
            "--warmup",
            "0",
            "-q",
        ],
        capsys,
    )
    assert code == 0, err
    assert not read_exr(cold / "o.0008.exr").same_pixels(reference[8])


def test_dry_run_writes_nothing(
    sequence: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    code, stdout, err = run_cli(
        [
            "denoise",
            sequence / "in.####.exr",
            "-o",
            tmp_path / "o" / "o.####.exr",
            "--dry-run",
            "--chunk-size",
            "3",
            "--warmup",
            "2",
            "-q",
        ],
        capsys,
    )
    assert code == 0, err
    assert "chunk 0: process 1-3" in stdout and "chunk 1: process 2-6" in stdout
    assert not (tmp_path / "o").exists()


def test_compression_follows_input_and_lossy_data_is_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    write_sequence(tmp_path / "seq", [1], compression="piz")
    code, _, err = run_cli(
        ["denoise", tmp_path / "seq" / "in.0001.exr", "-o", tmp_path / "o.exr", "-q"], capsys
    )
    assert code == 0, err
    assert read_exr(tmp_path / "o.exr").header["compression"] == OpenEXR.PIZ_COMPRESSION
    code, _, err = run_cli(
        [
            "denoise",
            tmp_path / "seq" / "in.0001.exr",
            "-o",
            tmp_path / "d.exr",
            "--compression",
            "dwaa",
            "--debug-aovs",
        ],
        capsys,
    )
    assert code == 2 and "dwaa" in err and not (tmp_path / "d.exr").exists()


def test_params_options_override_the_preset(
    sequence: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    code, stdout, err = run_cli(
        [
            "denoise",
            sequence / "in.0001.exr",
            "-o",
            tmp_path / "o.exr",
            "--frames",
            "1",
            "--preset",
            "falcor",
            "--sigma-luminance",
            "6",
            "--no-temporal",
        ],
        capsys,
    )
    assert code == 0, err
    params = json.loads(read_exr(tmp_path / "o.exr").header["svgf/params"])
    assert params["alpha"] == PRESETS["falcor"].alpha
    assert params["sigma_luminance"] == 6.0 and params["temporal"] is False
    assert "sigma_luminance=6.0" in stdout
    code, _, err = run_cli(
        ["denoise", sequence / "in.0001.exr", "-o", tmp_path / "p.exr", "--alpha", "1.5"], capsys
    )
    assert code == 2
    assert err == "ERROR: Invalid value for '--alpha': 1.5 is not in the range 0.0<x<=1.0.\n"


def test_json_progress(sequence: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    code, stdout, err = run_cli(
        [
            "denoise",
            sequence / "in.####.exr",
            "-o",
            tmp_path / "o.####.exr",
            "--frames",
            "3-4",
            "--warmup",
            "1",
            "--progress",
            "json",
        ],
        capsys,
    )
    assert code == 0, err
    events = [json.loads(line) for line in stdout.splitlines()]  # stdout is only JSON
    assert [e["event"] for e in events] == ["warmup", "frame_done", "frame_done", "done"]
    assert events[1]["frame"] == 3 and events[1]["index"] == 1 and events[1]["total"] == 2
    assert "svgf 0.1.0" in err  # start-up information moved to stderr


def test_explicit_file_list_and_directory_output(
    sequence: Path,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    reference: dict[int, ExrImage],
) -> None:
    files = [sequence / f"in.{f:04d}.exr" for f in FRAMES]  # the warm start's 8 frames too
    before = [f.read_bytes() for f in files]
    code, _, err = run_cli(["denoise", *files, "-o", f"{tmp_path / 'd'}/", "-q"], capsys)
    assert code == 0, err
    assert [p.name for p in sorted((tmp_path / "d").iterdir())] == [f.name for f in files]
    for frame in (3, 7):
        assert read_exr(tmp_path / "d" / f"in.{frame:04d}.exr").same_pixels(reference[frame])
    assert [f.read_bytes() for f in files] == before  # inputs untouched


BUNDLED = Path(__file__).resolve().parents[1] / "testdata" / "seq"


@pytest.mark.skipif(not (BUNDLED / "in.0010.exr").exists(), reason="bundled sequence absent")
def test_bundled_sequence_end_to_end(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    code, stdout, err = run_cli(
        ["denoise", BUNDLED / "in.####.exr", "-o", tmp_path / "den.####.exr"], capsys
    )
    assert code == 0, err
    assert "emission: emission.R, emission.G, emission.B" in stdout
    denoised = read_exr(tmp_path / "den.0010.exr")
    noisy = read_exr(BUNDLED / "in.0010.exr")
    ref = read_exr(BUNDLED / "ref.0010.exr").rgb()
    assert denoised.rgb().shape == (3, 72, 128)
    assert np.array_equal(denoised.header["worldToCamera"], noisy.header["worldToCamera"])
    assert denoised.header["svgf/kind"] == "denoised"
    assert denoised.header["svgf/frame"] == 10

    err_denoised = np.mean((denoised.rgb() - ref) ** 2)
    err_noisy = np.mean((noisy.rgb() - ref) ** 2)
    assert err_denoised < 0.5 * err_noisy  # the filter removes most of the 1-spp noise


def test_atrous_iterations_take_a_count_or_auto(
    sequence: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``auto`` (the default preset's value, -1 in ``svgf/params``) and counts 0-12 are
    accepted and logged as given; anything else, or a feedback index auto cannot reach on
    every image, is refused with exit 2."""
    first = [sequence / "in.0001.exr", "--frames", "1"]
    code, stdout, err = run_cli(
        ["denoise", *first, "-o", tmp_path / "a.exr", "--preset", "paper",
         "--atrous-iterations", "auto", "--feedback-iteration", "2"], capsys)
    assert code == 0, err
    assert json.loads(read_exr(tmp_path / "a.exr").header["svgf/params"])[
        "atrous_iterations"] == -1
    assert "atrous_iterations=auto" in stdout
    assert re.search(r"A-trous: 3 iterations \(auto, for \d+x\d+\)", stdout)
    for bad, message in [("seven", "'seven': expected a number of iterations or 'auto'"),
                         ("13", "13: must lie in 0..12 or be 'auto'")]:
        code, _, err = run_cli(["denoise", *first, "-o", tmp_path / "b.exr",
                                "--atrous-iterations", bad], capsys)
        assert code == 2 and message in err
    code, _, err = run_cli(["denoise", *first, "-o", tmp_path / "c.exr",
                            "--feedback-iteration", "3"], capsys)
    assert code == 2 and "below --atrous-iterations (3)" in err
    assert not (tmp_path / "b.exr").exists() and not (tmp_path / "c.exr").exists()


def test_every_frame_is_decoded_once(
    sequence: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """The first frame, decoded to fix the signal set, is the run's first read too
    (run.workers.FirstRead): every frame is decoded once (the first one was twice), and the
    outputs are the same; a colour-only run (no pass-through channels) reads it again."""
    import svgf_cli.io.exr as exr

    reads: list[str] = []
    real = exr.read_frame

    def counting(path, *args, **kwargs):  # noqa: ANN001, ANN002, ANN003, ANN202
        reads.append(Path(path).name)
        return real(path, *args, **kwargs)

    monkeypatch.setattr(exr, "read_frame", counting)
    out = tmp_path / "den"
    code, _, err = run_cli(["denoise", sequence / "in.####.exr", "-o", out / "den.####.exr",
                            "--warm-start", "0"], capsys)
    assert code == 0, err
    assert sorted(reads) == [f"in.{f:04d}.exr" for f in FRAMES]
    monkeypatch.setattr("svgf_cli.run.workers.FirstRead.__call__",
                        lambda self, path, mapping, *, passthrough=True:
                        real(path, mapping, mapping.motion_convention,
                             passthrough=passthrough))
    assert run_cli(["denoise", sequence / "in.####.exr", "-o", tmp_path / "twice" /
                    "den.####.exr", "--warm-start", "0"], capsys)[0] == 0
    for f in FRAMES:
        once = read_exr(out / f"den.{f:04d}.exr")
        twice = read_exr(tmp_path / "twice" / f"den.{f:04d}.exr")
        assert once.channels.keys() == twice.channels.keys()
        for name, plane in once.channels.items():
            assert np.array_equal(plane.view(np.uint8), twice.channels[name].view(np.uint8))
    monkeypatch.undo()
    monkeypatch.setattr(exr, "read_frame", counting)
    reads.clear()
    assert run_cli(["denoise", sequence / "in.####.exr", "-o", tmp_path / "colour" /
                    "den.####.exr", "--warm-start", "0", "--colour-only"], capsys)[0] == 0
    assert reads.count("in.0001.exr") == 2 and len(reads) == len(FRAMES) + 1


def test_verbose_says_what_several_samples_per_pixel_change(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """`-v` on Blender's 4-sample frames names the blends and the anti-lag window they get;
    on one-sample frames, or with the count forced to 1, it says nothing of samples."""
    cycles = BUNDLED.parent / "cycles"
    args = ["denoise", "--preset-aovs", "cycles", "-v", "--frames", "1"]
    code, stdout, err = run_cli([*args, cycles / "roll4" / "in.0001.exr", "-o",
                                 tmp_path / "a.exr"], capsys)
    assert code == 0, err
    assert ("Samples: 4 per pixel (the header's): the light blends at 0.59, the colours' means"
            " at 0.358, anti-lag window radius 1") in stdout
    for extra, frame in (([], "roll"), (["--set", "samples_per_pixel=1"], "roll4")):
        code, stdout, err = run_cli([*args, *extra, cycles / frame / "in.0001.exr", "-o",
                                     tmp_path / f"{frame}{len(extra)}.exr"], capsys)
        assert code == 0, err
        assert "Samples:" not in stdout
