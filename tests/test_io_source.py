"""The in-memory layout of an EXR file (io/source.py) and the C-level stderr capture that keeps
OpenEXR's own error lines out of the log."""

from __future__ import annotations

import os
import threading

import numpy as np
import OpenEXR
import pytest

from svgf_cli.errors import InputError
from svgf_cli.io.output import synthetic_source, write_output
from svgf_cli.io.source import capture_c_stderr, capture_library_output, decode_source


def test_c_stderr_keeps_library_errors_and_passes_every_other_line_through(capfd) -> None:
    with capture_c_stderr() as captured:
        os.write(2, b"another thread's warning\n")
        os.write(2, b"EXR Error (EXR_ERR_CORRUPT_CHUNK): bad chunk\n")
        os.write(2, b"last line\n")
    assert captured == ["EXR Error (EXR_ERR_CORRUPT_CHUNK): bad chunk"]
    assert capfd.readouterr().err == "another thread's warning\nlast line\n"


def test_c_stderr_capture_steps_aside_without_a_stderr(monkeypatch, capfd) -> None:
    # A farm daemon may run with no usable file descriptor 2 (os.dup fails): decoding must
    # go on, with nothing captured and nothing written elsewhere.
    def no_stderr(fd: int) -> int:
        raise OSError(9, "Bad file descriptor")

    with monkeypatch.context() as patch:
        patch.setattr(os, "dup", no_stderr)
        with capture_c_stderr() as captured:
            os.write(2, b"EXR Error (EXR_ERR_CORRUPT_CHUNK): bad chunk\n")
    assert captured == []
    assert capfd.readouterr() == ("", "EXR Error (EXR_ERR_CORRUPT_CHUNK): bad chunk\n")


def test_library_output_is_captured_for_this_thread_only(capsys) -> None:
    # The bindings print a part's decode failure: the reading thread keeps it as the reason;
    # what another thread prints meanwhile (a progress line) still reaches stdout.
    other = threading.Thread(target=print, args=("another thread's line",))
    failure = "Warning: Exception raised reading pixel data for part 1 - bad chunk"
    with capture_library_output() as printed:
        print(failure)
        other.start()
        other.join()
    assert "".join(printed) == failure + "\n"
    assert capsys.readouterr().out == "another thread's line\n"


def test_synthetic_source_writes_scalar_attributes_and_the_alpha(tmp_path) -> None:
    alpha = np.linspace(0.0, 1.0, 12, dtype=np.float32).reshape(3, 4)
    source = synthetic_source(tmp_path / "in.exr", (3, 4),
                              {"owner": "lighting", "frameNumber": 7, "notes": ["a", "b"]},
                              alpha=alpha)
    header = source.parts[0].header
    assert header["owner"] == "lighting" and header["frameNumber"] == 7
    assert "notes" not in header  # not an EXR attribute type: never written
    colour = np.full((3, 4), 0.5, np.float32)
    out = tmp_path / "out.exr"
    write_output(out, source, part_index=0, attributes={},
                 channels={"R": colour, "G": colour, "B": colour})
    with OpenEXR.File(str(out), separate_channels=True) as written:
        channels = {n: c.pixels.copy() for n, c in written.channels().items()}
        sampling = (written.channels()["A"].xSampling, written.channels()["A"].ySampling)
        # Written as renderers write an alpha: not flagged perceptually linear (a hint that
        # makes lossy codecs treat the channel as a colour difference).
        p_linear = written.channels()["A"].pLinear
        header = dict(written.header())
    assert np.array_equal(channels["A"], alpha) and sampling == (1, 1) and not p_linear
    assert all(np.array_equal(channels[c], colour) for c in "RGB")
    assert header["owner"] == "lighting"
    for window in ("dataWindow", "displayWindow"):
        assert [list(corner) for corner in header[window]] == [[0, 0], [3, 2]]


def test_software_names_svgf_once(tmp_path) -> None:
    # Absent: just the tag; the renderer's: appended; already there (an svgf output
    # denoised again): left as it is.
    colour = np.full((2, 2), 0.5, np.float32)
    found = []
    for before in (None, "Blender 4.5.3", "Blender 4.5.3; svgf 0.1.0"):
        source = synthetic_source(tmp_path / "in.exr", (2, 2),
                                  {"Software": before} if before else None)
        out = tmp_path / "out.exr"
        write_output(out, source, part_index=0, attributes={}, software="svgf 0.1.0",
                     channels={"R": colour, "G": colour, "B": colour})
        with OpenEXR.File(str(out)) as written:
            found.append(written.header()["Software"])
    assert found == ["svgf 0.1.0", "Blender 4.5.3; svgf 0.1.0", "Blender 4.5.3; svgf 0.1.0"]


def test_a_truncated_two_part_file_reports_the_first_library_error(tmp_path) -> None:
    # Cut inside part "a": the core library prints the precise cause for it, then a vaguer
    # line ("Corrupt chunk offset") for part "b"; the message must carry the precise one.
    rng = np.random.default_rng(15)
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    parts = [OpenEXR.Part(dict(header), {c: rng.random((64, 64), np.float32) for c in "RGB"},
                          name) for name in ("a", "b")]
    whole = tmp_path / "whole.exr"
    OpenEXR.File(parts).write(str(whole))
    data = whole.read_bytes()
    decoded = decode_source(whole)  # the part count read from the file itself
    assert [part.name for part in decoded.parts] == ["a", "b"]
    assert np.array_equal(decoded.parts[1].channels["G"].pixels,
                          parts[1].channels["G"].pixels)
    cut = tmp_path / "cut.exr"
    cut.write_bytes(data[: int(len(data) * 0.3)])
    with pytest.raises(InputError, match=r"cannot read pixels: .*found corrupt leader") as error:
        decode_source(cut)
    assert "Corrupt chunk offset" not in str(error.value)


class _SkippingDecoder:
    """Stands in for OpenEXR.File the way the bindings fail on a bad part: they skip it,
    and may print why (instead of raising)."""

    said = ""

    def __init__(self, path: str, **_: object) -> None:
        if self.said:
            print(self.said)
        self.parts: list[object] = []

    def __enter__(self) -> _SkippingDecoder:
        return self

    def __exit__(self, *_: object) -> None:
        return None


@pytest.mark.parametrize(
    ("said", "reason"),
    [("Warning: Exception raised reading pixel data for part 1 - bad chunk", "bad chunk"),
     ("", "a part could not be decoded")],
)
def test_a_skipped_part_is_reported_in_the_bindings_words(
    tmp_path, monkeypatch, said: str, reason: str
) -> None:
    monkeypatch.setattr(_SkippingDecoder, "said", said)
    monkeypatch.setattr(OpenEXR, "File", _SkippingDecoder)
    with pytest.raises(InputError) as raised:
        decode_source(tmp_path / "in.exr", expected_parts=2)
    assert str(raised.value) == f"{tmp_path / 'in.exr'}: cannot read pixels: {reason}"


def test_a_file_the_bindings_cannot_open_is_an_input_error(tmp_path) -> None:
    path = tmp_path / "in.exr"
    path.write_bytes(b"v/1\x01" + bytes(64))  # the magic number, then nothing valid
    with pytest.raises(InputError) as raised:
        decode_source(path, expected_parts=1)
    message = str(raised.value)
    assert message.startswith(f"{path}: cannot read pixels: ") and "\n" not in message


def test_released_channels_drop_their_pixels_and_keep_their_place() -> None:
    # The colour the writer replaces is released right after the read: its memory is freed,
    # its name and part stay for the writer.
    alpha = np.ones((2, 3), np.float32)
    source = synthetic_source("in.exr", (2, 3), alpha=alpha)
    source.release("A")
    source.release("not there")  # nothing to free: no error
    channel = source.parts[0].channels["A"]
    assert channel.pixels is None and channel.type_name == "float"
