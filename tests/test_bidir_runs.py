"""`svgf denoise --bidirectional` on files: chunks with warm-up on both sides, resume, the
scratch folder's life, the plan, and what is refused."""

from __future__ import annotations

import io
import json
import os
import signal
from pathlib import Path

import numpy as np
import pytest
from exr_fixtures import ExrImage, read_exr
from test_cli_support import exit_code, reference_run, run_cli, sequence_folder

from svgf_cli.farm.plan import plan_chunks
from svgf_cli.filters.params import resolve_params
from svgf_cli.io.layers import build_mapping
from svgf_cli.io.spill import ScratchFolder
from svgf_cli.progress import Progress
from svgf_cli.run.chunk import run_sequence
from svgf_cli.run.stop import Interrupted, StopFlag
from svgf_cli.run.tasks import FrameTask, RunConfig

FRAMES = range(1, 11)


@pytest.fixture(scope="module")
def sequence(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return sequence_folder(tmp_path_factory, FRAMES)


@pytest.fixture(scope="module")
def scratch(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tmp_path_factory.mktemp("scratch")


@pytest.fixture(scope="module")
def one_run(sequence: Path, scratch: Path,
            tmp_path_factory: pytest.TempPathFactory) -> dict[int, ExrImage]:
    """One uninterrupted bidirectional run (float colour): frame -> its output."""
    outputs = reference_run(tmp_path_factory, sequence, "--float", "--bidirectional",
                            "--scratch-dir", scratch)
    return {f: read_exr(p) for f, p in outputs.items()}


def _args(sequence: Path, out: Path, scratch: Path, *extra: object) -> list[object]:
    return ["denoise", sequence / "in.####.exr", "-o", out / "o.####.exr", "--float",
            "--bidirectional", "--scratch-dir", scratch, *extra]


def test_chunks_with_warmup_all_equal_one_run(
    sequence: Path, scratch: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str],
    one_run: dict[int, ExrImage],
) -> None:
    code, stdout, err = run_cli(_args(sequence, tmp_path, scratch, "--chunk-size", "4",
                                      "--warmup", "all"), capsys)
    assert code == 0, err
    for f in FRAMES:
        assert read_exr(tmp_path / f"o.{f:04d}.exr").same_pixels(one_run[f]), f
    # each chunk's forward pass reports its frames, and the percentage counts both passes
    assert "(forward pass, frame 1, 1/10)" in stdout and "Progress: 100% (frame" in stdout
    assert list(scratch.iterdir()) == []  # every run removed its scratch folder


def test_chunks_without_temporal_albedo_equal_one_run(
    sequence: Path, scratch: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str],
    tmp_path_factory: pytest.TempPathFactory, one_run: dict[int, ExrImage],
) -> None:
    # The default runs (the colour means travel through the spill and the reverse pass's
    # state) are checked above; the same without the means, which change the output.
    whole = {f: read_exr(p) for f, p in reference_run(
        tmp_path_factory, sequence, "--float", "--bidirectional", "--no-temporal-albedo",
        "--scratch-dir", scratch).items()}
    code, _, err = run_cli(_args(sequence, tmp_path, scratch, "--no-temporal-albedo",
                                 "--chunk-size", "4", "--warmup", "all"), capsys)
    assert code == 0, err
    for f in FRAMES:
        assert read_exr(tmp_path / f"o.{f:04d}.exr").same_pixels(whole[f]), f
    assert any(not whole[f].same_pixels(one_run[f]) for f in FRAMES)


def test_it_differs_from_the_causal_run_most_on_the_first_frame(
    sequence: Path, tmp_path_factory: pytest.TempPathFactory, one_run: dict[int, ExrImage],
) -> None:
    causal = {f: read_exr(p) for f, p in reference_run(tmp_path_factory, sequence,
                                                      "--float", "--warm-start", 0).items()}
    change = [float(np.abs(one_run[f].rgb() - causal[f].rgb()).mean()) for f in FRAMES]
    assert min(change) > 0  # the later frames count everywhere
    assert change[0] > change[4]  # a cold causal start is where it shows most


def test_numeric_warmup_reads_after_the_chunk_too(
    sequence: Path, scratch: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str],
    one_run: dict[int, ExrImage],
) -> None:
    code, stdout, err = run_cli(_args(sequence, tmp_path, scratch, "--frames", "4-6",
                                      "--warmup", "2", "--dry-run"), capsys)
    assert code == 0, err
    assert "chunk 0: process 2-8 (7 frames, 4 history-only), write 4-6" in stdout
    code, _, err = run_cli(_args(sequence, tmp_path, scratch, "--frames", "4-6",
                                 "--warmup", "3"), capsys)
    assert code == 0, err
    frame = read_exr(tmp_path / "o.0005.exr").rgb()
    exact = one_run[5].rgb()
    assert 0 < np.abs(frame - exact).mean() / np.abs(exact).mean() < 0.05


def test_resume_with_skip_existing_gives_the_same_frames(
    sequence: Path, scratch: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str],
    one_run: dict[int, ExrImage],
) -> None:
    # What an interrupted reverse pass leaves: the last frames (its warm-up with --frames
    # reaches back to frame 1, so they are exact).
    code, _, err = run_cli(_args(sequence, tmp_path, scratch, "--frames", "7-10"), capsys)
    assert code == 0, err
    code, stdout, err = run_cli(_args(sequence, tmp_path, scratch, "--skip-existing"), capsys)
    assert code == 0, err
    assert "4 existing skipped" in stdout
    for f in FRAMES:
        assert read_exr(tmp_path / f"o.{f:04d}.exr").same_pixels(one_run[f]), f


def test_a_bad_frame_fails_the_run_and_removes_the_scratch(
    sequence: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str],
) -> None:
    broken = tmp_path / "in"
    broken.mkdir()
    for f in FRAMES:
        data = (sequence / f"in.{f:04d}.exr").read_bytes()
        (broken / f"in.{f:04d}.exr").write_bytes(data[: len(data) // 2] if f == 6 else data)
    scratch = tmp_path / "scratch"
    code, _, err = run_cli(_args(broken, tmp_path, scratch), capsys)
    assert code == 3 and "in.0006.exr" in err
    assert list(scratch.iterdir()) == []
    assert not list(tmp_path.glob("o.*.exr"))  # outputs come from the reverse pass only


def test_a_dead_runs_scratch_is_removed_and_a_live_ones_kept(tmp_path: Path) -> None:
    with ScratchFolder(tmp_path) as live:
        name = live.path.name
        assert live.path.stat().st_mode & 0o777 == 0o700  # private to the user who runs svgf
        dead_pid = 2**22 + 12345
        while _alive(dead_pid):
            dead_pid += 1
        host_ns, _, rest = name[len(".svgf-scratch."):].partition(".")
        dead = tmp_path / f".svgf-scratch.{host_ns}.{dead_pid}.{rest.split('.')[-1]}"
        dead.mkdir()
        (dead / "3.exr").write_bytes(b"x")
        other = tmp_path / "keep.me"
        other.mkdir()
        with ScratchFolder(tmp_path) as second:
            assert not dead.exists() and live.path.exists() and other.exists()
            assert second.path != live.path
    assert sorted(p.name for p in tmp_path.iterdir()) == ["keep.me"]


def test_stale_scratch_behind_a_live_one_is_removed(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # Whatever order the folder lists them in: a live run's folder first does not end the
    # scan before the dead ones.
    from svgf_cli.io.spill import remove_stale_scratch

    with ScratchFolder(tmp_path) as live:
        host_ns, _, rest = live.path.name[len(".svgf-scratch."):].partition(".")
        dead_pid = 2**22 + 12345
        while _alive(dead_pid):
            dead_pid += 1
        dead = tmp_path / f".svgf-scratch.{host_ns}.{dead_pid}.{rest.split('.')[-1]}"
        dead.mkdir()
        listed = Path.iterdir
        monkeypatch.setattr(Path, "iterdir", lambda self: iter(
            sorted(listed(self), key=lambda p: p != live.path)))
        assert remove_stale_scratch(tmp_path) == [dead]
        assert live.path.exists() and not dead.exists()


def test_a_scratch_folder_of_another_pid_namespace_is_kept(tmp_path: Path) -> None:
    # Same host, another PID namespace (a container on this node): its PIDs mean nothing
    # here, so even a PID that is dead here does not make its folder stale.
    with ScratchFolder(tmp_path) as live:
        host, _, rest = live.path.name[len(".svgf-scratch."):].partition(".")
        host_name, _, namespace = host.rpartition("_")
        dead_pid = 2**22 + 12345
        while _alive(dead_pid):
            dead_pid += 1
        other = tmp_path / (f".svgf-scratch.{host_name}_{int(namespace) + 1}.{dead_pid}."
                            f"{rest.split('.')[-1]}")
        other.mkdir()
        with ScratchFolder(tmp_path):
            assert other.exists()


def test_a_failed_scratch_write_is_a_one_line_error(tmp_path: Path) -> None:
    from svgf_cli.errors import SvgfError

    with ScratchFolder(tmp_path) as scratch:
        os.rmdir(scratch.path)  # e.g. a cleanup job removed it
        planes = {"a.R": np.zeros((2, 3), np.float16)}
        with pytest.raises(SvgfError, match="cannot write scratch file"):
            scratch.write(1, planes, {"a.R": 1.0})


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def test_plan_adds_the_warmup_after_each_chunk() -> None:
    chunks = plan_chunks(list(range(1, 11)), list(range(1, 13)), chunk_size=4, warmup=2,
                         bidirectional=True)
    assert [(c.read_start, c.read_end) for c in chunks] == [(1, 6), (3, 10), (7, 12)]
    every = plan_chunks(list(range(3, 8)), list(range(1, 13)), chunk_size=2, warmup=None,
                        bidirectional=True)
    assert {(c.read_start, c.read_end) for c in every} == {(1, 12)}
    causal = plan_chunks(list(range(1, 11)), list(range(1, 13)), chunk_size=4, warmup=2)
    assert [c.read_end for c in causal] == [4, 8, 10]


def test_refused_combinations(sequence: Path, tmp_path: Path) -> None:
    assert exit_code(_args(sequence, tmp_path, tmp_path, "--save-history", "h.npz")) == 2
    assert exit_code(["denoise", sequence / "in.####.exr", "-o", tmp_path / "o.####.exr",
                      "--scratch-dir", tmp_path]) == 2


def test_evaluate_compares_forward_with_bidirectional(
    tmp_path: Path, capsys: pytest.CaptureFixture[str],
) -> None:
    seq = Path(__file__).resolve().parent.parent / "testdata" / "seq"
    report = tmp_path / "r.json"
    code, stdout, err = run_cli(
        ["evaluate", seq / "ref.####.exr", "-r", seq / "ref.####.exr", "-i", seq / "in.####.exr",
         "--frames", "1-3", "--baseline", "forward", "--baseline", "bidirectional", "-q",
         "--json", report], capsys)
    assert code == 0, err
    methods = {m["name"]: m for m in json.loads(report.read_text())["methods"]}
    forward = [f["relmse"] for f in methods["forward"]["frames"]]
    both = [f["relmse"] for f in methods["bidirectional"]["frames"]]
    assert len(forward) == len(both) == 3 and forward != both
    assert both[0] < forward[0]  # the cold start is where the later frames help most


class _StopAfter(StopFlag):
    """A stop request (SIGTERM) that arrives after ``polls`` frames were finished."""

    def __init__(self, polls: int) -> None:
        super().__init__()
        self._left = polls

    def __bool__(self) -> bool:
        self._left -= 1
        if self._left < 0:
            self.signum = signal.SIGTERM
        return self.signum is not None


@pytest.mark.parametrize(("polls", "written"), [(3, []), (12, [10, 9, 8])])
def test_a_signal_stops_either_pass_and_removes_the_scratch(
    sequence: Path, tmp_path: Path, polls: int, written: list[int],
    one_run: dict[int, ExrImage],
) -> None:
    """Stopped in the forward pass (nothing written) or in the reverse one (the last frames
    written, complete and exact): the scratch folder is gone either way."""
    scratch = tmp_path / "scratch"
    config = RunConfig(params=resolve_params("default", bidirectional=True), preset="default",
                       mapping=build_mapping("svgf"), float_colour=True, scratch_dir=scratch)
    tasks = [FrameTask(f, sequence / f"in.{f:04d}.exr", tmp_path / f"o.{f:04d}.exr")
             for f in FRAMES]
    quiet = Progress("lines", 10, quiet=True, out=io.StringIO(), err=io.StringIO())
    with pytest.raises(Interrupted) as stopped:
        run_sequence(tasks, config, quiet, stop=_StopAfter(polls))
    assert stopped.value.exit_code == 143
    assert list(scratch.iterdir()) == []
    assert sorted(int(p.name.split(".")[1]) for p in tmp_path.glob("o.*.exr")) == sorted(written)
    for f in written:
        assert read_exr(tmp_path / f"o.{f:04d}.exr").same_pixels(one_run[f]), f


def test_svgf_plan_sees_bidirectional_among_the_denoise_arguments(
    capsys: pytest.CaptureFixture[str],
) -> None:
    plan = ["plan", "--frames", "1-10", "--chunk-size", "4", "--warmup", "2",
            "--last-frame", "12", "--", "in.####.exr", "-o", "o.####.exr"]
    code, stdout, err = run_cli([*plan, "--bidirectional"], capsys)
    assert code == 0, err
    assert [c["read"] for c in json.loads(stdout)] == [[1, 6], [3, 10], [7, 12]]
    code, stdout, _ = run_cli([*plan, "--set", "warm_start=0"], capsys)
    assert [c["read"] for c in json.loads(stdout)] == [[1, 4], [3, 8], [7, 10]]
    # The default preset's warm start: each chunk's first output has 2 frames of warm-up,
    # fewer than 8, so each chunk looks ahead 16 frames from its start (to the last frame).
    code, stdout, _ = run_cli(plan, capsys)
    assert [c["read"] for c in json.loads(stdout)] == [[1, 12], [3, 12], [7, 12]]
    code, stdout, _ = run_cli([*plan, "--warm-start", "4"], capsys)
    assert [c["read"] for c in json.loads(stdout)] == [[1, 8], [3, 10], [7, 12]]
    assert exit_code(plan[:7] + ["--last-frame", "9", "--", "i.####.exr", "-o", "o"]) == 2


def test_scratch_folder_makes_its_missing_parents_and_removes_itself(tmp_path: Path) -> None:
    # `--scratch-dir /local/scratch/job42` need not exist yet on a fresh farm node.
    parent = tmp_path / "scratch" / "job42"
    with ScratchFolder(parent) as folder:
        assert folder.path.is_dir() and folder.path.parent == parent
    assert parent.is_dir() and list(parent.iterdir()) == []
