"""File-sequence patterns and frame specs, in the conventions render farms already use.

Pattern tokens (only in the file name, never in the directory part):

* ``####`` -- one padded digit per ``#`` (``####`` = 4 digits); a lone ``#`` means 4-padded,
  as in fileseq, because that is what ``render.#.exr`` means in Nuke/fileseq pipelines;
* ``@``, ``@@@@`` -- one padded digit per ``@`` (``@`` = unpadded);
* ``%04d`` / ``%d`` -- printf style;
* ``$F4`` / ``$F`` -- Houdini style;
* a concrete frame path such as ``shot.1001.exr`` (noice style): the last digit group before
  the extension is the frame number and its width is the padding;
* a plain file name with no digits is a single file, not a sequence.

Frame specs (fileseq / Deadline syntax): ``1001-1100``, ``1,5,7-9``, ``1001-1100x2`` (also
``1001-1100:2``, the OpenJD form), ``5``.
"""

from __future__ import annotations

import os
import re
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path

from svgf_cli.errors import InputError, UsageError

# One range item of a frame spec: "5", "1-10", "1-10x2", "1-10:2".
_SPEC_ITEM = re.compile(r"^(\d+)(?:-(\d+)(?:[x:](\d+))?)?$")

# Explicit tokens, in the order they are tried. Each yields the padding width.
_TOKEN = re.compile(r"(?P<hash>#+)|(?P<at>@+)|%(?P<printf>0?\d*)d|\$F(?P<houdini>\d*)")
# The last run of digits in a name (the frame number of a concrete path).
_LAST_DIGITS = re.compile(r"(\d+)(?!.*\d)")


def parse_frame_spec(spec: str) -> list[int]:
    """Frames named by a spec such as ``"1001-1100"``, ``"1,5,7-9"``, ``"1001-1100x2"``.

    Returns the sorted unique frame numbers; raises ValueError with a message that quotes
    the bad part of the spec.
    """
    text = spec.strip()
    if not text:
        raise ValueError("empty frame spec (expected e.g. 1001-1100, 1,5,7-9 or 1001-1100x2)")
    frames: set[int] = set()
    for raw_item in text.split(","):
        item = raw_item.strip().replace(" ", "")
        match = _SPEC_ITEM.match(item)
        if match is None:
            raise ValueError(
                f"bad frame spec item {raw_item.strip()!r} in {spec!r} "
                "(expected N, A-B or A-BxSTEP with non-negative integers)"
            )
        start = int(match.group(1))
        end = int(match.group(2)) if match.group(2) is not None else start
        step = int(match.group(3)) if match.group(3) is not None else 1
        if step < 1:
            raise ValueError(f"frame spec item {item!r}: step must be at least 1")
        if end < start:
            raise ValueError(f"frame spec item {item!r}: range runs backwards ({start} > {end})")
        frames.update(range(start, end + 1, step))
    return sorted(frames)


def format_frame_spec(frames: Iterable[int]) -> str:
    """The shortest-ish spec for ``frames``: consecutive runs as ``A-B``, others comma-joined.

    ``parse_frame_spec(format_frame_spec(f)) == sorted(set(f))`` for non-negative frames.
    """
    ordered = sorted(set(frames))
    parts: list[str] = []
    i = 0
    while i < len(ordered):
        j = i
        while j + 1 < len(ordered) and ordered[j + 1] == ordered[j] + 1:
            j += 1
        parts.append(str(ordered[i]) if i == j else f"{ordered[i]}-{ordered[j]}")
        i = j + 1
    return ",".join(parts)


def _split_extension(name: str) -> tuple[str, str]:
    """``("shot.1001", ".exr")``; a name without a dot has an empty extension."""
    dot = name.rfind(".")
    if dot <= 0:
        return name, ""
    return name[:dot], name[dot:]


@dataclass(frozen=True)
class SequencePattern:
    """A numbered file sequence (or a single file): directory, prefix, padding, suffix."""

    text: str
    directory: Path
    prefix: str
    suffix: str
    padding: int
    is_sequence: bool

    @classmethod
    def parse(cls, text: str) -> SequencePattern:
        """Parse a pattern, a concrete frame path, or a plain file (see the module docstring)."""
        if not text:
            raise UsageError("empty file pattern")
        path = Path(text)
        directory, name = path.parent, path.name
        if _TOKEN.search(str(directory)) and not _TOKEN.search(name):
            raise UsageError("frame tokens are only allowed in the file name", text)
        tokens = list(_TOKEN.finditer(name))
        if len(tokens) > 1:
            raise UsageError("more than one frame token in the file name", text)
        if tokens:
            token = tokens[0]
            if token.group("hash") is not None:
                width = len(token.group("hash"))
                padding = 4 if width == 1 else width
            elif token.group("at") is not None:
                padding = len(token.group("at"))
            elif token.group("printf") is not None:
                digits = token.group("printf").lstrip("0")
                padding = int(digits) if digits else 1
            else:
                digits = token.group("houdini")
                padding = int(digits) if digits else 1
            return cls(
                text=text,
                directory=directory,
                prefix=name[: token.start()],
                suffix=name[token.end() :],
                padding=max(padding, 1),
                is_sequence=True,
            )
        stem, extension = _split_extension(name)
        match = _LAST_DIGITS.search(stem)
        if match is None:
            return cls(text, directory, name, "", 0, is_sequence=False)
        return cls(
            text=text,
            directory=directory,
            prefix=stem[: match.start()],
            suffix=stem[match.end() :] + extension,
            padding=len(match.group(1)),
            is_sequence=True,
        )

    @property
    def display(self) -> str:
        """The pattern in ``#`` form (``@`` when unpadded), for logs and plans."""
        if not self.is_sequence:
            return str(self.directory / self.prefix)
        token = "@" if self.padding == 1 else "#" * self.padding
        return str(self.directory / f"{self.prefix}{token}{self.suffix}")

    def format_frame(self, frame: int) -> str:
        if frame < 0:
            raise ValueError(f"negative frame number {frame} is not supported")
        return f"{frame:0{self.padding}d}"

    def path(self, frame: int) -> Path:
        """The file for ``frame`` (the single file itself when this is not a sequence)."""
        if not self.is_sequence:
            return self.directory / self.prefix
        return self.directory / f"{self.prefix}{self.format_frame(frame)}{self.suffix}"

    def frame_of(self, path: str | os.PathLike[str]) -> int | None:
        """The frame number ``path`` stands for, or None when it is not part of this sequence.

        Only the file name is compared; the digits must be exactly what ``path(frame)``
        would write (so ``0012`` is frame 12 for 4-padding but not for 3-padding).
        """
        if not self.is_sequence:
            return None
        name = Path(path).name
        if not (name.startswith(self.prefix) and name.endswith(self.suffix)):
            return None
        digits = name[len(self.prefix) : len(name) - len(self.suffix)]
        if not digits.isdigit() or not digits.isascii():
            return None
        frame = int(digits)
        return frame if self.format_frame(frame) == digits else None

    def frames_on_disk(self) -> list[int]:
        """Sorted frame numbers whose files exist (dot-files such as temporaries ignored)."""
        if not self.is_sequence:
            return [0] if self.path(0).is_file() else []
        folder = self.directory if str(self.directory) else Path(".")
        try:
            entries = list(os.scandir(folder))
        except (FileNotFoundError, NotADirectoryError):
            return []
        except PermissionError as exc:
            raise InputError(f"cannot list directory: {exc.strerror}", str(folder)) from exc
        frames: list[int] = []
        for entry in entries:
            if entry.name.startswith("."):
                continue
            frame = self.frame_of(entry.name)
            if frame is not None and entry.is_file():
                frames.append(frame)
        return sorted(frames)

    def with_directory(self, directory: str | os.PathLike[str]) -> SequencePattern:
        """The same naming in another directory (output given as a folder keeps the padding)."""
        return SequencePattern(
            text=str(Path(directory) / Path(self.text).name),
            directory=Path(directory),
            prefix=self.prefix,
            suffix=self.suffix,
            padding=self.padding,
            is_sequence=self.is_sequence,
        )


def has_frame_token(text: str) -> bool:
    """True when ``text`` holds an explicit frame token (``#``, ``@``, ``%04d``, ``$F``)."""
    return _TOKEN.search(Path(text).name) is not None


def expand_inputs(inputs: Sequence[str]) -> list[tuple[int, Path]]:
    """Turn the command-line inputs into ``(frame, path)`` pairs sorted by frame.

    * one pattern or concrete frame path: every frame of that sequence found on disk;
    * one plain file without digits: ``[(0, file)]``;
    * several files: each must exist; frame numbers come from each name's last digit group,
      or ``0..n-1`` in the order given when any name has no digits.
    """
    if not inputs:
        raise UsageError("no input files given")
    if len(inputs) == 1:
        pattern = SequencePattern.parse(inputs[0])
        if not pattern.is_sequence:
            if not pattern.path(0).is_file():
                raise InputError("input file not found", inputs[0])
            return [(0, pattern.path(0))]
        frames = pattern.frames_on_disk()
        if not frames:
            where = pattern.directory if str(pattern.directory) else Path(".")
            reason = "no files match the pattern"
            if not where.is_dir():
                reason += f" (directory {where} does not exist)"
            raise InputError(reason, inputs[0])
        return [(frame, pattern.path(frame)) for frame in frames]

    for text in inputs:
        if has_frame_token(text):
            raise UsageError("give one pattern or a list of files, not several patterns", text)
        if not Path(text).is_file():
            raise InputError("input file not found", text)
    numbers: list[int | None] = []
    for text in inputs:
        match = _LAST_DIGITS.search(_split_extension(Path(text).name)[0])
        numbers.append(int(match.group(1)) if match else None)
    if any(n is None for n in numbers):
        return [(i, Path(text)) for i, text in enumerate(inputs)]
    seen: dict[int, str] = {}
    for number, text in zip(numbers, inputs, strict=True):
        assert number is not None
        if number in seen:
            raise InputError(f"same frame number {number} as {seen[number]}", text)
        seen[number] = text
    return sorted((number, Path(text)) for number, text in seen.items())
