"""Scratch files of a bidirectional run: named planes per frame, written once, read back once.

A bidirectional run's forward pass writes each output frame's state (named (H, W) planes,
half or float, plus a few float factors) to a private scratch folder; the reverse pass reads
them back in reverse order and deletes each once read, so the disk use falls as the run
ends. Each file is one ZIP-compressed EXR, readable by any EXR tool: written by
`zipchunks` (zlib-ng's deflate), read by the OpenEXR library.

The folder is ``.svgf-scratch.HOST_NS.PID.TOKEN`` under the chosen parent (the system
temporary folder by default, never the output folder) and is removed when the run ends,
however it ends (``with ScratchFolder(...)``); a folder left by a process that was killed
(SIGKILL) is removed by the next run on the same host (`remove_stale_scratch`).
"""

from __future__ import annotations

import contextlib
import json
import os
import re
import secrets
import shutil
import tempfile
from pathlib import Path

import numpy as np
import OpenEXR

from svgf_cli.errors import SvgfError
from svgf_cli.io import zipchunks
from svgf_cli.io.atomic import _host, _pid_alive, _pid_namespace

_PREFIX = ".svgf-scratch."
_NAME_RE = re.compile(r"^\.svgf-scratch\.(?P<host>[A-Za-z0-9-]+)_(?P<ns>\d+)\.(?P<pid>\d+)\.")
_FACTORS = "svgf/factors"


def default_parent() -> Path:
    """The system temporary folder (``$TMPDIR``, else ``/tmp``)."""
    return Path(tempfile.gettempdir())


def remove_stale_scratch(parent: Path) -> list[Path]:
    """Remove scratch folders under ``parent`` left by dead processes of this host and PID
    namespace (a killed run cannot clean up); returns what was removed."""
    removed: list[Path] = []
    try:
        entries = list(parent.iterdir())
    except OSError:
        return removed
    for entry in entries:
        match = _NAME_RE.match(entry.name)
        if match is None or not entry.is_dir():
            continue
        if match["host"] != _host() or int(match["ns"]) != _pid_namespace():
            continue
        if _pid_alive(int(match["pid"])):
            continue
        shutil.rmtree(entry, ignore_errors=True)
        removed.append(entry)
    return removed


class ScratchFolder:
    """A private folder of per-frame plane files, removed on ``close`` (or leaving the
    ``with`` block, on success, error or signal)."""

    def __init__(self, parent: Path | None = None) -> None:
        parent = Path(parent) if parent is not None else default_parent()
        try:
            parent.mkdir(parents=True, exist_ok=True)
            remove_stale_scratch(parent)
            name = f"{_PREFIX}{_host()}_{_pid_namespace()}.{os.getpid()}.{secrets.token_hex(4)}"
            self.path = parent / name
            self.path.mkdir(mode=0o700)
        except OSError as exc:
            raise SvgfError(
                f"cannot create the scratch folder: {exc.strerror or exc} (--scratch-dir "
                "chooses another)", str(parent)) from None
        self.bytes_written = 0

    def _file(self, frame: int) -> Path:
        return self.path / f"{frame}.exr"

    def write(self, frame: int, planes: dict[str, np.ndarray], factors: dict[str, float]
              ) -> None:
        """Store frame ``frame``'s planes (float16 or float32 (H, W) arrays, one shape)."""
        height, width = next(iter(planes.values())).shape if planes else (0, 0)
        attributes = zipchunks.scanline_attributes(width, height,
                                                   strings={_FACTORS: json.dumps(factors)})
        path = self._file(frame)
        try:
            writer = zipchunks.ChunkWriter(attributes, planes, {})
            with open(path, "wb") as fh:
                writer.write(fh)
            self.bytes_written += path.stat().st_size
        except (OSError, zipchunks.Declined) as exc:
            raise SvgfError(f"cannot write scratch file: {exc}", str(path)) from None

    def read(self, frame: int) -> tuple[dict[str, np.ndarray], dict[str, float]]:
        """Frame ``frame``'s planes and factors, then its file is deleted."""
        path = self._file(frame)
        try:
            with OpenEXR.File(str(path), separate_channels=True) as exr:
                part = exr.parts[0]
                planes = {name: channel.pixels for name, channel in part.channels.items()}
                factors = json.loads(part.header[_FACTORS])
        except (OSError, RuntimeError, KeyError, ValueError) as exc:
            raise SvgfError(f"cannot read scratch file: {exc}", str(path)) from None
        with contextlib.suppress(OSError):
            path.unlink()
        return planes, {k: float(v) for k, v in factors.items()}

    def close(self) -> None:
        shutil.rmtree(self.path, ignore_errors=True)

    def __enter__(self) -> ScratchFolder:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()
