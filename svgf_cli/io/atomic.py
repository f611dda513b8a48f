"""Atomic, farm-safe file replacement: hidden unique temporaries, renamed into place.

Every file the tool writes (EXR frames, history files, reports) is written to a hidden
temporary in the destination folder and renamed onto the final name once complete, so a
reader (a compositor, another farm task, ``--skip-existing``) sees either the old file or the
complete new one, never a partial one. The temporary's name is unique across hosts,
containers and processes (host name, PID namespace, PID and a random token), because two farm
nodes may write the same frame to shared storage at once, and containerised nodes are often
all PID 1. It starts with a dot and keeps the final extension, so it never matches a frame
pattern and writers that pick a format by extension still work.

``stale_temporaries`` finds temporaries that dead runs left behind, for cleaning on resume:
ours only (the name parses and names one of the given outputs), and only when the writer is
provably dead (this host and PID namespace, PID gone) or the file has not been touched for
``STALE_AFTER_SECONDS`` (another host: a live write touches its file continually).
"""

from __future__ import annotations

import contextlib
import os
import re
import secrets
import socket
import time
from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

# A temporary of another host (whose PIDs we cannot check) untouched for this long is dead.
STALE_AFTER_SECONDS = 3600.0

_TEMP_RE = re.compile(
    r"^\.(?P<name>.+)\.(?P<host>[A-Za-z0-9-]+)_(?P<ns>\d+)\.(?P<pid>\d+)\.(?P<token>[0-9a-f]{8})"
    r"\.tmp(?P<ext>\.[A-Za-z0-9]+)?$"
)


def _host() -> str:
    """This host's name reduced to ``[A-Za-z0-9-]`` (dots would make names ambiguous)."""
    name = re.sub(r"[^A-Za-z0-9-]+", "-", socket.gethostname()).strip("-")
    return name[:40] or "host"


def _pid_namespace() -> int:
    """Inode of this process's PID namespace: PIDs are only comparable within one."""
    try:
        return os.stat("/proc/self/ns/pid").st_ino
    except OSError:
        return 0


def temporary_path(path: str | os.PathLike[str]) -> Path:
    """A fresh hidden sibling of ``path``: ``.NAME.HOST_NS.PID.TOKEN.tmp.EXT``.

    Unique per call (random token), per process and per host/container; hidden (leading
    dot), and ending in ``path``'s own extension.
    """
    path = Path(path)
    ext = path.suffix if re.fullmatch(r"\.[A-Za-z0-9]+", path.suffix or "") else ""
    token = secrets.token_hex(4)
    return path.with_name(
        f".{path.name}.{_host()}_{_pid_namespace()}.{os.getpid()}.{token}.tmp{ext}"
    )


@dataclass(frozen=True)
class TemporaryName:
    """What a temporary's name says about its writer."""

    target: str  # the final file name it was going to become
    host: str
    namespace: int
    pid: int


def parse_temporary(name: str) -> TemporaryName | None:
    """Parse a name made by `temporary_path` (None for any other name)."""
    match = _TEMP_RE.match(name)
    if match is None:
        return None
    return TemporaryName(
        match["name"], match["host"], int(match["ns"]), int(match["pid"])
    )


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # exists, owned by someone else
        return True
    return True


def stale_temporaries(
    outputs: Iterable[str | os.PathLike[str]], *, now: float | None = None
) -> list[Path]:
    """Temporaries of ``outputs`` whose writers are dead (see the module docstring).

    A temporary written by a live run, here or on another host, is never returned: on this
    host and PID namespace its PID is alive; elsewhere its modification time is recent.
    """
    now = time.time() if now is None else now
    by_folder: dict[Path, set[str]] = {}
    for output in outputs:
        output = Path(output)
        by_folder.setdefault(output.parent, set()).add(output.name)
    here = (_host(), _pid_namespace())
    stale: list[Path] = []
    for folder, names in by_folder.items():
        try:
            entries = list(os.scandir(folder))
        except OSError:
            continue
        for entry in entries:
            parsed = parse_temporary(entry.name)
            if parsed is None or parsed.target not in names:
                continue
            try:
                age = now - entry.stat(follow_symlinks=False).st_mtime
            except OSError:
                continue
            same_namespace = (parsed.host, parsed.namespace) == here
            writer_dead = (
                same_namespace and parsed.pid != os.getpid() and not _pid_alive(parsed.pid)
            )
            if writer_dead or age > STALE_AFTER_SECONDS:
                stale.append(Path(entry.path))
    return sorted(stale)


def remove_stale_temporaries(outputs: Iterable[str | os.PathLike[str]]) -> list[Path]:
    """Delete `stale_temporaries` (ignoring files that vanish meanwhile); return them."""
    removed = []
    for path in stale_temporaries(outputs):
        with contextlib.suppress(FileNotFoundError):
            path.unlink()
            removed.append(path)
    return removed


@contextmanager
def atomic_target(path: str | os.PathLike[str]) -> Iterator[Path]:
    """Yield a temporary path to write; on success rename it onto ``path``.

    On any exception the temporary is removed and the exception propagates unchanged (a
    failing cleanup never hides the real cause); ``path`` is left as it was.
    """
    final = Path(path)
    tmp = temporary_path(final)
    try:
        yield tmp
        os.replace(tmp, final)
    except BaseException:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise


def write_atomically(
    path: str | os.PathLike[str], write: Callable[[Path], None]
) -> None:
    """``write(tmp)`` then rename ``tmp`` onto ``path`` (see `atomic_target`)."""
    with atomic_target(path) as tmp:
        write(tmp)
