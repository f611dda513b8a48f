"""The look-ahead warm start of a cold start (``--warm-start N``, the default preset's 4;
run.warm_start): the first N output frames take a bidirectional run's colour, every later
frame is the causal run's bit for bit, the light layers add up to the warm colour, and
chunked or resumed runs reproduce the uninterrupted one."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import OpenEXR
import pytest
import reference_svgf as ref
from test_cli_support import exit_code, reference_run, sequence_folder

from svgf_cli.farm.plan import plan_chunks
from svgf_cli.filters.params import PRESETS
from svgf_cli.run.history import HistoryFile, check_history_params
from svgf_cli.run.tasks import FrameTask
from svgf_cli.run.warm_start import warm_head

ROOT = Path(__file__).resolve().parents[1]
SHOT = ROOT / "testdata/cycles/production"
FRAMES = list(range(1, 11))


def pixels(path: Path) -> dict[str, np.ndarray]:
    with OpenEXR.File(str(path), separate_channels=True) as exr:
        return {n: c.pixels.copy() for n, c in exr.parts[0].channels.items()}


def colour(path: Path, prefix: str = "") -> np.ndarray:
    chans = pixels(path)
    return np.stack([chans[f"{prefix}{c}"].astype(np.float64) for c in "RGB"])


@pytest.fixture(scope="module")
def sequence(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return sequence_folder(tmp_path_factory, FRAMES)


@pytest.fixture(scope="module")
def warm(tmp_path_factory: pytest.TempPathFactory, sequence: Path) -> dict[int, Path]:
    return reference_run(tmp_path_factory, sequence, "--warm-start", 3)


@pytest.fixture(scope="module")
def cold(tmp_path_factory: pytest.TempPathFactory, sequence: Path) -> dict[int, Path]:
    return reference_run(tmp_path_factory, sequence, "--warm-start", 0)


# ------------------------------------------------------------------------------ the plan


def test_a_cold_chunk_looks_ahead_twice_its_warm_frames() -> None:
    timeline = list(range(1, 21))
    chunks = plan_chunks(list(range(1, 21)), timeline, chunk_size=5, warmup=2, warm_start=4)
    assert chunks[0].lookahead_end == 8  # frames 1-4 warmed over 1-8; the chunk ends at 5
    assert chunks[0].to_json()["read"] == [1, 8]
    # Later chunks start with 2 warm-up frames: their first output is their 3rd frame, still
    # within the first 4 of a cold filter, so they too look ahead from their first frame.
    assert chunks[1].read_start == 4 and chunks[1].lookahead_end == 11
    assert all(c.lookahead_end is None for c in plan_chunks(
        timeline, timeline, chunk_size=5, warmup=4, warm_start=4)[1:])
    assert plan_chunks(timeline, timeline, chunk_size=5, warmup=2, warm_start=0)[0] \
        .lookahead_end is None
    assert plan_chunks(timeline, timeline, chunk_size=5, warmup=2, warm_start=4,
                       bidirectional=True)[0].lookahead_end is None
    short = plan_chunks([1, 2], [1, 2, 3], chunk_size=None, warmup=None, warm_start=4)
    assert short[0].lookahead_end == 3  # clamped at the timeline's end


def test_the_head_writes_only_the_warm_frames_of_a_cold_start() -> None:
    tasks = [FrameTask(f, Path(f"in.{f}"), Path(f"out.{f}"), lookahead_only=f > 5)
             for f in range(1, 9)]
    head = warm_head(tasks, 2)
    assert [t.frame for t in head] == [1, 2, 3, 4]
    assert [t.output is not None for t in head] == [True, True, False, False]
    assert not any(t.lookahead_only for t in warm_head(tasks, 4))
    warmed_up = [FrameTask(f, Path(f"in.{f}"), Path(f"out.{f}") if f > 3 else None)
                 for f in range(1, 9)]
    assert warm_head(warmed_up, 3) == []  # its first output has 3 frames of history
    assert [t.frame for t in warm_head(warmed_up, 4) if t.output] == [4]
    assert warm_head(tasks, 0) == []


def test_a_history_file_does_not_pin_the_warm_start(tmp_path: Path) -> None:
    params = PRESETS["default"]
    saved = HistoryFile(tmp_path / "h.npz", {}, 3, params.replace(warm_start=0).to_json(), 4, 4)
    check_history_params(saved, params)  # warm_start differs: not the filter's state
    other = HistoryFile(tmp_path / "h.npz", {}, 3, params.replace(alpha=0.1).to_json(), 4, 4)
    with pytest.raises(Exception, match="alpha"):
        check_history_params(other, params)


# ------------------------------------------------------------------------------ runs


def test_warm_frames_take_the_bidirectional_colour_and_the_rest_are_causal(
    tmp_path: Path, sequence: Path, warm: dict[int, Path], cold: dict[int, Path]
) -> None:
    bidir = tmp_path / "bidir"
    assert exit_code(["denoise", sequence / "in.####.exr", "-o", bidir / "o.####.exr", "-q",
                      "--bidirectional", "--frames", "1-3", "--warmup", "3"]) == 0
    for f in (1, 2, 3):
        got = colour(warm[f])
        assert np.array_equal(got, colour(bidir / f"o.{f:04d}.exr"))
        assert not np.array_equal(got, colour(cold[f]))
    for f in FRAMES[3:]:
        assert pixels(warm[f]).keys() == pixels(cold[f]).keys()
        for name, plane in pixels(warm[f]).items():
            assert np.array_equal(plane, pixels(cold[f])[name]), (f, name)
    with OpenEXR.File(str(warm[1]), separate_channels=True) as exr:
        params = json.loads(exr.header()["svgf/params"])
    assert params["warm_start"] == 3


def test_chunked_and_resumed_runs_reproduce_the_warm_start(
    tmp_path: Path, sequence: Path, warm: dict[int, Path]
) -> None:
    chunked = tmp_path / "chunked"
    assert exit_code(["denoise", sequence / "in.####.exr", "-o", chunked / "o.####.exr", "-q",
                      "--warm-start", 3, "--chunk-size", 2, "--warmup", "all"]) == 0
    for f in FRAMES:
        assert np.array_equal(colour(chunked / f"o.{f:04d}.exr"), colour(warm[f])), f
    # A resume after frame 2 was lost: frame 2's filter is still within the warm frames.
    (chunked / "o.0002.exr").unlink()
    (chunked / "o.0003.exr").unlink()
    assert exit_code(["denoise", sequence / "in.####.exr", "-o", chunked / "o.####.exr", "-q",
                      "--warm-start", 3, "--skip-existing"]) == 0
    for f in (2, 3):
        assert np.array_equal(colour(chunked / f"o.{f:04d}.exr"), colour(warm[f])), f


def test_the_log_counts_only_the_frames_written(
    tmp_path: Path, sequence: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "o.####.exr"
    code = exit_code(["denoise", sequence / "in.####.exr", "-o", out, "--frames", "1-4",
                      "--warm-start", 3, "-v", "--progress", "lines"])
    text = capsys.readouterr().out
    assert code == 0
    assert "warm start: frame(s) 1-3 from a bidirectional run over frames 1-6" in text
    assert "Done: 4 frame(s) written, 4 processed" in text
    assert "look ahead" not in text and "warm start looks ahead to 6" in text
    assert sorted(p.name for p in tmp_path.glob("o.*.exr")) == [
        f"o.{f:04d}.exr" for f in range(1, 5)]


def test_light_layers_add_up_to_the_warm_colour(tmp_path: Path) -> None:
    out = tmp_path / "den"
    assert exit_code(["denoise", SHOT / "in.####.exr", "-o", out / "o.####.exr", "-q",
                      "--preset-aovs", "cycles", "--frames", "1-2", "--warm-start", 2]) == 0
    for f in (1, 2):
        chans = pixels(out / f"o.{f:04d}.exr")
        total = colour(out / f"o.{f:04d}.exr", "ViewLayer.Combined.")
        groups = sum(np.stack([chans[f"ViewLayer.Combined_{g}.{c}"].astype(np.float64)
                               for c in "RGB"]) for g in ("env", "fill", "key"))
        scale = np.maximum(np.abs(total), 1e-3)
        assert np.max(np.abs(groups - total) / scale) < 3e-3


def test_svgf_plan_reads_the_look_ahead_of_the_preset_or_the_option(
    capsys: pytest.CaptureFixture[str]
) -> None:
    def reads(*denoise_args: str) -> list[list[int]]:
        assert exit_code(["plan", "--frames", "1-20", "--chunk-size", "5", "--format", "json",
                          "--", "in.####.exr", "-o", "o.####.exr", *denoise_args]) == 0
        return [c["read"] for c in json.loads(capsys.readouterr().out)]

    assert reads()[0] == [1, 16]  # the default preset's 8: frames 1-8 look ahead to 16
    assert reads("--preset", "paper")[0] == [1, 5]
    assert reads("--preset=paper", "--warm-start", "6")[0] == [1, 12]
    assert reads("--set", "warm_start=0")[0] == [1, 5]
    assert reads("--bidirectional")[0] == [1, 20]  # its own reverse warm-up instead


def test_a_bad_frame_in_the_look_ahead_leaves_the_frames_before_it_causal(
    tmp_path: Path, sequence: Path, cold: dict[int, Path], capsys: pytest.CaptureFixture[str]
) -> None:
    broken = tmp_path / "seq"
    broken.mkdir()
    for f in FRAMES:
        (broken / f"in.{f:04d}.exr").write_bytes((sequence / f"in.{f:04d}.exr").read_bytes())
    (broken / "in.0005.exr").write_bytes(b"not an exr")
    out = tmp_path / "out"
    code = exit_code(["denoise", broken / "in.####.exr", "-o", out / "o.####.exr", "-q",
                      "--warm-start", 3])
    err = capsys.readouterr().err
    assert code == 3
    assert err.startswith(f"ERROR: {broken / 'in.0005.exr'}: ") and err.count("\n") == 1
    # The look-ahead (frames 1-6) met the bad frame: no warm start; the causal run wrote
    # every frame before it, as without one.
    assert sorted(p.name for p in out.iterdir()) == [f"o.{f:04d}.exr" for f in range(1, 5)]
    for f in range(1, 5):
        assert np.array_equal(colour(out / f"o.{f:04d}.exr"), colour(cold[f])), f


def test_taa_anti_aliases_the_warm_frames(tmp_path: Path, sequence: Path) -> None:
    """TAA (forced) with a warm start: the look-ahead anti-aliases the warm colours
    backwards in time and they go through the causal run's TAA. The first two frames differ
    from the run without TAA only on their outlines' pixels."""
    out = {}
    for taa in ("true", "false"):
        folder = tmp_path / f"taa-{taa}"
        assert exit_code(["denoise", sequence / "in.####.exr", "-o", folder / "o.####.exr",
                          "-q", "--frames", "1-3", "--set", f"taa={taa}", "--warm-start", 3,
                          "--float", "--colour-only"]) == 0
        out[taa] = [colour(folder / f"o.{f:04d}.exr") for f in (1, 2)]
    for index, frame in enumerate((1, 2)):
        depth = pixels(sequence / f"in.{frame:04d}.exr")["Z"].astype(np.float64)
        depth[~np.isfinite(depth)] = 0.0
        changed = np.any(out["true"][index] != out["false"][index], axis=0)
        assert changed.any() and not changed[~ref.taa_outline(depth)].any(), frame
