"""Write safety that a plausible bug would break (issue 15, item 3).

* outputs are renamed into place, never copied or written under the final name;
* temporary names are hidden, keep the extension, and are unique per host, PID namespace,
  process and call (two containerised farm nodes are both PID 1);
* history files are atomic: a failure inside the write leaves no partial file;
* stale temporaries of dead runs are cleaned, live ones (here or on other hosts) never;
* frame planes shared with the passed-through source are not modified by the Denoiser.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import OpenEXR
import pytest
from exr_fixtures import PartSpec, bits_equal, gbuffer, read_parts, write_parts

from svgf_cli.filters.params import SVGFParams
from svgf_cli.io import atomic, zipchunks
from svgf_cli.io.atomic import (
    STALE_AFTER_SECONDS,
    parse_temporary,
    remove_stale_temporaries,
    stale_temporaries,
    temporary_path,
)
from svgf_cli.io.exr import ExrWriteError, output_error, read_frame, write_exr
from svgf_cli.io.layers import build_mapping
from svgf_cli.io.output import write_output
from svgf_cli.run.history import load_history, save_history


@pytest.mark.parametrize("codec", ["zip", "piz"])  # zipchunks' writer, the library's
def test_output_is_the_renamed_temporary_never_written_in_place(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, codec: str
) -> None:
    source_path = write_parts(tmp_path / "in.0001.exr", [PartSpec(gbuffer())])
    source = read_frame(source_path, build_mapping()).source
    target = tmp_path / "out.0001.exr"
    target.write_bytes(b"previous frame")  # an earlier output being replaced
    written: list[str] = []
    inode_of_temporary: list[int] = []
    real_write = OpenEXR.File.write
    real_replace = os.replace

    def spy_write(self, name):  # the library must only ever write the temporary
        written.append(str(name))
        return real_write(self, name)

    def spy_replace(src, dst):
        inode_of_temporary.append(os.stat(src).st_ino)
        assert Path(dst).read_bytes() == b"previous frame"  # untouched until the rename
        return real_replace(src, dst)

    real_chunks = zipchunks.ChunkWriter.write

    def spy_chunks(self, fh, threads=0):  # so must the chunk writer (ZIP parts)
        written.append(str(fh.name))
        return real_chunks(self, fh, threads)

    monkeypatch.setattr(OpenEXR.File, "write", spy_write)
    monkeypatch.setattr(zipchunks.ChunkWriter, "write", spy_chunks)
    monkeypatch.setattr(atomic.os, "replace", spy_replace)
    colour = {c: np.ones((8, 12), np.float32) for c in "RGB"}
    write_output(target, source, part_index=0, channels=colour, attributes={},
                 compression=codec)
    assert len(written) == 1 and Path(written[0]).name.startswith(".out.0001.exr.")
    assert Path(written[0]).parent == tmp_path and written[0] != str(target)
    # Renamed, not copied: the final file is the very inode the library wrote.
    assert inode_of_temporary == [os.stat(target).st_ino]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["in.0001.exr", "out.0001.exr"]


def test_simple_writer_renames_too(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    inodes: list[int] = []
    real_replace = os.replace

    def spy_replace(src, dst):
        inodes.append(os.stat(src).st_ino)
        return real_replace(src, dst)

    monkeypatch.setattr(atomic.os, "replace", spy_replace)
    write_exr(tmp_path / "o.exr", {"R": np.ones((4, 4), np.float32)})
    assert inodes == [os.stat(tmp_path / "o.exr").st_ino]


def test_temporary_names_are_hidden_unique_and_never_match_a_pattern(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    final = tmp_path / "den.0042.exr"
    # Two containerised farm nodes: same host name, both PID 1.
    monkeypatch.setattr(atomic.socket, "gethostname", lambda: "render.node-7.farm")
    monkeypatch.setattr(atomic.os, "getpid", lambda: 1)
    names = {temporary_path(final).name for _ in range(50)}
    assert len(names) == 50  # the random token differs per call
    for name in names:
        assert name.startswith(".den.0042.exr.render-node-7-farm_") and name.endswith(".tmp.exr")
        parsed = parse_temporary(name)
        assert parsed is not None
        assert (parsed.target, parsed.host, parsed.pid) == ("den.0042.exr", "render-node-7-farm", 1)
        (tmp_path / name).touch()
    # Hidden, and nothing a frame pattern (or a shell glob of outputs) matches.
    assert not [p for p in tmp_path.glob("den.*.exr")]
    assert not any(re.fullmatch(r"den\.\d+\.exr", n) for n in names)


def _dead_pid() -> int:
    proc = subprocess.Popen([sys.executable, "-c", "pass"])
    proc.wait()
    return proc.pid


def test_stale_temporaries_only_ours_and_only_dead(tmp_path: Path) -> None:
    outputs = [tmp_path / f"o.{f:04d}.exr" for f in (1, 2)]
    host_ns = f"{atomic._host()}_{atomic._pid_namespace()}"
    dead = tmp_path / f".o.0001.exr.{host_ns}.{_dead_pid()}.0123abcd.tmp.exr"
    live = tmp_path / f".o.0002.exr.{host_ns}.{os.getppid()}.89abcdef.tmp.exr"
    remote = tmp_path / ".o.0001.exr.otherhost_4026531836.12.00ff00ff.tmp.exr"
    remote_old = tmp_path / ".o.0002.exr.otherhost_4026531836.13.00ff00fe.tmp.exr"
    not_ours = tmp_path / f".x.0001.exr.{host_ns}.{_dead_pid()}.0123abce.tmp.exr"
    foreign = tmp_path / ".o.0001.exr.partial"
    for path in (dead, live, remote, remote_old, not_ours, foreign):
        path.write_bytes(b"partial")
    old = time.time() - STALE_AFTER_SECONDS - 60
    os.utime(remote_old, (old, old))
    assert stale_temporaries(outputs) == sorted([dead, remote_old])
    assert remove_stale_temporaries(outputs) == sorted([dead, remote_old])
    left = {p.name for p in tmp_path.iterdir()}
    assert left == {live.name, remote.name, not_ours.name, foreign.name}


def test_another_hosts_temporary_is_stale_after_an_hour_untouched(tmp_path: Path) -> None:
    # docs/robustness.md: a temporary of another host (PIDs not checkable) is removed once it
    # has been untouched for an hour; a live write touches it continually.
    outputs = [tmp_path / "o.0001.exr"]
    remote = tmp_path / ".o.0001.exr.otherhost_4026531836.12.00ff00ff.tmp.exr"
    remote.write_bytes(b"partial")
    touched = 1_000_000_000.0
    os.utime(remote, (touched, touched))
    assert stale_temporaries(outputs, now=touched + 3599.5) == []
    assert stale_temporaries(outputs, now=touched + 3600.5) == [remote]


def test_a_live_process_of_another_user_keeps_its_temporary(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # Farm users share output folders: kill(pid, 0) on another user's live process is
    # refused (EPERM), and that process is still writing its temporary.
    theirs, real_kill = 4242, os.kill

    def kill(pid: int, sig: int) -> None:
        if pid == theirs:
            raise PermissionError(1, "Operation not permitted")
        real_kill(pid, sig)

    monkeypatch.setattr(os, "kill", kill)
    host_ns = f"{atomic._host()}_{atomic._pid_namespace()}"
    (tmp_path / f".o.0001.exr.{host_ns}.{theirs}.0123abcd.tmp.exr").write_bytes(b"partial")
    assert stale_temporaries([tmp_path / "o.0001.exr"]) == []


def test_temporaries_are_ours_without_a_proc_filesystem(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # macOS and BSD farms have no /proc: the temporary's name must still parse as ours, or
    # an interrupted run's temporaries would never be cleaned up.
    real_stat = os.stat

    def stat(path, *args, **kwargs):
        if str(path) == "/proc/self/ns/pid":
            raise FileNotFoundError(2, "No such file or directory", str(path))
        return real_stat(path, *args, **kwargs)

    monkeypatch.setattr(os, "stat", stat)
    parsed = parse_temporary(temporary_path(tmp_path / "o.0001.exr").name)
    assert parsed is not None and parsed.target == "o.0001.exr" and parsed.pid == os.getpid()


def test_history_file_is_atomic(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    path = tmp_path / "h.npz"
    state = {"colour": np.arange(24, dtype=np.float32).reshape(2, 3, 4)}
    save_history(path, state, 7, SVGFParams(), (3, 4), tmp_path / "in.0007.exr")
    before = path.read_bytes()
    real_savez = np.savez

    def failing_savez(handle, **payload):
        handle.write(b"PK\x03\x04 half a zip")  # something reached the disk...
        raise OSError(28, "No space left on device")  # ...then the disk filled up

    monkeypatch.setattr(np, "savez", failing_savez)
    with pytest.raises(Exception, match="No space left on device") as raised:
        save_history(path, state, 8, SVGFParams(), (3, 4), tmp_path / "in.0008.exr")
    assert str(path) in str(raised.value)
    monkeypatch.setattr(np, "savez", real_savez)
    assert path.read_bytes() == before  # the previous history is intact
    assert sorted(p.name for p in tmp_path.iterdir()) == ["h.npz"]  # no temporary left
    assert load_history(path).last_frame == 7


def test_killed_history_write_leaves_only_a_hidden_temporary(tmp_path: Path) -> None:
    """SIGKILL inside np.savez: the final name never holds a partial file."""
    path = tmp_path / "h.npz"
    script = f"""
import numpy as np, os, signal
from pathlib import Path
from svgf_cli.filters.params import SVGFParams
from svgf_cli.run.history import save_history
real = np.savez
def dying(handle, **payload):
    handle.write(b"PK partial")
    handle.flush()
    os.kill(os.getpid(), signal.SIGKILL)
np.savez = dying
save_history(Path({str(path)!r}), {{"a": np.zeros(3)}}, 1, SVGFParams(), (1, 3), Path("x"))
"""
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True)
    assert proc.returncode == -9
    assert not path.exists()
    leftovers = list(tmp_path.iterdir())
    assert len(leftovers) == 1 and leftovers[0].name.startswith(".h.npz.")
    assert stale_temporaries([path]) == leftovers  # and a resume would clean it


def test_failed_write_reports_the_real_cause(tmp_path: Path) -> None:
    source_path = write_parts(tmp_path / "in.0001.exr", [PartSpec(gbuffer())])
    source = read_frame(source_path, build_mapping()).source
    colour = {c: np.ones((8, 12), np.float32) for c in "RGB"}
    (tmp_path / "taken.exr").mkdir()
    cases = {
        tmp_path / "taken.exr": "is a directory",
        tmp_path / "missing" / "o.exr": "does not exist",
        source_path / "o.exr": "is not a directory",
    }
    for target, reason in cases.items():
        with pytest.raises(ExrWriteError) as raised:
            write_output(target, source, part_index=0, channels=colour, attributes={})
        message = str(raised.value)
        assert message.startswith(f"{target}: cannot write") and reason in message, message
        assert "\n" not in message
    assert sorted(p.name for p in tmp_path.iterdir()) == ["in.0001.exr", "taken.exr"]


def test_a_folder_removed_during_the_write_is_named(tmp_path: Path) -> None:
    # The folder checks pass, then the write fails: a farm cleanup removed the folder (its
    # name is the cause), or only the file's temporary vanished (the system's words).
    gone = tmp_path / "gone" / "o.exr"
    missing = FileNotFoundError(2, "No such file or directory")
    assert str(output_error(missing, gone)) == (
        f"{gone}: cannot write: folder {gone.parent} does not exist")
    here = tmp_path / "o.exr"
    assert str(output_error(missing, here)) == f"{here}: cannot write: No such file or directory"
    # A folder that appeared at the output's name is the cause, whatever the system said.
    taken = tmp_path / "taken.exr"
    taken.mkdir()
    busy = OSError(16, "Device or resource busy")
    assert str(output_error(busy, taken)) == f"{taken}: cannot write: is a directory"


def test_alpha_and_passthrough_values_that_are_not_defaults(tmp_path: Path) -> None:
    channels = dict(gbuffer())
    channels["A"] = np.linspace(0.0, 0.75, 96, dtype=np.float32).reshape(8, 12)
    channels["Z"][0, 0] = 1e10  # background depth: cleaned for the filter, not in the file
    channels["N.X"][1, 1] = 5.0  # not unit length: renormalised for the filter only
    source_path = write_parts(tmp_path / "in.0001.exr", [PartSpec(channels)])
    result = read_frame(source_path, build_mapping())
    assert result.frame.depth[0, 0] == 0 and np.isclose(
        np.linalg.norm(result.frame.normal[:, 1, 1]), 1.0
    )
    colour = {c: np.full((8, 12), 2.0, np.float32) for c in "RGB"}
    write_output(tmp_path / "o.exr", result.source, part_index=0, channels=colour, attributes={})
    (_, _, out), = read_parts(tmp_path / "o.exr")
    for name in ("A", "Z", "N.X", "albedo.G", "motion.X", "id"):
        assert bits_equal(out[name], channels[name]), name


def test_denoiser_leaves_shared_frame_planes_alone(tmp_path: Path) -> None:
    """The reader lets the passthrough source reference the frame's unchanged planes (one
    copy in memory): a Denoiser that wrote into its input frame would corrupt the output."""
    from svgf_cli.filters.denoiser import Denoiser

    denoiser = Denoiser(SVGFParams())
    for frame_number in (1, 2, 3):
        channels = dict(gbuffer(frame_number))
        for c in "RGB":
            channels[f"direct.{c}"] = channels[c] * 0.6
            channels[f"indirect.{c}"] = channels[c] * 0.4
        path = write_parts(tmp_path / f"in.{frame_number}.exr", [PartSpec(channels)])
        result = read_frame(path, build_mapping())
        shared = result.source.parts[0].channels["indirect.G"].pixels
        indirect = result.frame.signal("indirect").radiance
        assert np.shares_memory(shared, indirect)  # the memory saving is real
        snapshot = {n: c.pixels.copy() for n, c in result.source.parts[0].channels.items()
                    if c.pixels is not None}
        denoiser.process(result.frame)
        for name, before in snapshot.items():
            assert bits_equal(result.source.parts[0].channels[name].pixels, before), name
