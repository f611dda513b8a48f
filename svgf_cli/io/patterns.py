"""File-sequence patterns and frame specs, in the conventions render farms already use.

Frame sets and padding widths come from ``fileseq`` (the VFX standard); this module adds the
pieces fileseq does not cover (see each one's comment).

Pattern tokens (only in the file name, never in the directory part), padding style
``fileseq.PAD_STYLE_HASH1`` (one digit per ``#``, as Nuke, Houdini and Deadline write it):

* ``####`` -- one padded digit per ``#``; a *lone* ``#`` means 4 digits (fileseq's default
  ``HASH4`` reading, what ``render.#.exr`` means in fileseq pipelines);
* ``@``, ``@@@@`` -- one padded digit per ``@`` (``@`` = unpadded);
* ``%04d`` / ``%d`` -- printf style;
* ``$F4`` / ``$F`` -- Houdini style;
* a concrete frame path such as ``shot.1001.exr`` (noice style): the last digit group before
  the extension is the frame number and its width is the padding;
* a plain file name with no digits is a single file, not a sequence.

Negative frames are written with their sign inside the padding (``####`` and -5 give
``-005``), as fileseq and printf do.

Frame specs (fileseq syntax, also Deadline's): ``1001-1100``, ``1,5,7-9``, ``1001-1100x2``
(every 2nd), ``1001-1100y2`` (fileseq's inverse step: the frames ``x2`` leaves out),
``-10--1`` (negative frames), ``5``. ``A-B:N`` is a step too, as in OpenJD range expressions
(fileseq reads ``:`` as a staggered order of *all* frames, an order this tool cannot honour:
frames are always filtered in timeline order).
"""

from __future__ import annotations

import os
import re
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path

from fileseq import PAD_STYLE_HASH1, PAD_STYLE_HASH4, FileSequence, FrameSet
from fileseq.exceptions import FileSeqException, MaxSizeException

from svgf_cli.errors import InputError, UsageError

# More frames than any shot has (11.5 hours at 24 fps); a larger spec is a typo, and
# expanding it would only exhaust memory.
MAX_SPEC_FRAMES = 1_000_000

# Hand-kept: fileseq's grammar only finds a token right before the extension, so it cannot
# locate the one in ``shot_####_v2.exr``; this finds it anywhere in the name.
_TOKEN = re.compile(r"#+|@+|%0?\d*d|\$F\d*")
# Hand-kept (fileseq needs a dot before the frame of a concrete path): the last digit group,
# with a sign when it directly follows a dot (``shot.-005.exr``).
_LAST_DIGITS = re.compile(r"((?<=\.)-)?\d+(?!.*\d)")
_FRAME_DIGITS = re.compile(r"-?\d+")
_SPEC_HELP = "expected N, A-B, A-BxSTEP, A-BySTEP or a comma list; negative frames allowed"


def parse_frame_spec(spec: str) -> list[int]:
    """Frames named by a spec such as ``"1001-1100"``, ``"1,5,7-9"``, ``"1001-1100x2"``.

    Returns the sorted unique frame numbers; raises ValueError with a one-line message that
    quotes the bad part of the spec.
    """
    text = spec.strip()
    if not text:
        raise ValueError(f"empty frame spec ({_SPEC_HELP})")
    try:
        frames = FrameSet(text.replace(":", "x"))
    except MaxSizeException:
        raise ValueError(
            f"frame spec {spec!r} names more than {MAX_SPEC_FRAMES} frames"
        ) from None
    except FileSeqException:
        raise ValueError(f"{_bad_item(spec)} ({_SPEC_HELP})") from None
    if len(frames) > MAX_SPEC_FRAMES:
        raise ValueError(
            f"frame spec {spec!r} names {len(frames)} frames, more than {MAX_SPEC_FRAMES}"
        )
    if not frames:
        raise ValueError(f"frame spec {spec!r} names no frames")
    if frames.hasSubFrames():
        raise ValueError(f"frame spec {spec!r}: sub-frames are not supported")
    return sorted({int(frame) for frame in frames})


def _bad_item(spec: str) -> str:
    """``bad frame spec item '1-' in '1-,5'``: the first comma item fileseq refuses."""
    for item in spec.split(","):
        try:
            FrameSet(item.strip().replace(":", "x"))
        except FileSeqException:
            return f"bad frame spec item {item.strip()!r} in {spec!r}"
    return f"bad frame spec {spec!r}"


def format_frame_spec(frames: Iterable[int]) -> str:
    """The compact spec for ``frames`` (``1001-1025``, ``1-9x2``, ``1,5,7-9``).

    ``parse_frame_spec(format_frame_spec(f)) == sorted(set(f))``.
    """
    ordered = sorted(set(frames))
    return FrameSet.framesToFrameRange(ordered, sort=False, compress=False)


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
            return cls(
                text=text,
                directory=directory,
                prefix=name[: token.start()],
                suffix=name[token.end() :],
                padding=max(padding_width(token.group()), 1),
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
            padding=len(match.group()),
            is_sequence=True,
        )

    @property
    def display(self) -> str:
        """The pattern in ``#`` form (``@`` when unpadded), for logs and plans."""
        if not self.is_sequence:
            return str(self.directory / self.prefix)
        token = "@" if self.padding == 1 else hash_token(self.padding)
        return str(self.directory / f"{self.prefix}{token}{self.suffix}")

    def format_frame(self, frame: int) -> str:
        """Zero-padded to the pattern's width, a sign counting as a digit (``-005``)."""
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
        if not digits.isascii() or _FRAME_DIGITS.fullmatch(digits) is None:
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


def padding_width(token: str) -> int:
    """Digits a token stands for: ``####`` 4, ``#`` 4, ``@@`` 2, ``%04d`` 4, ``$F`` 1."""
    style = PAD_STYLE_HASH4 if token == "#" else PAD_STYLE_HASH1
    return FileSequence.getPaddingNum(token, pad_style=style)


def hash_token(width: int) -> str:
    """``#`` characters for ``width`` digits in our padding style (``####`` for 4)."""
    return FileSequence.getPaddingChars(width, pad_style=PAD_STYLE_HASH1)


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
        numbers.append(int(match.group()) if match else None)
    if any(n is None for n in numbers):
        return [(i, Path(text)) for i, text in enumerate(inputs)]
    seen: dict[int, str] = {}
    for number, text in zip(numbers, inputs, strict=True):
        assert number is not None
        if number in seen:
            raise InputError(f"same frame number {number} as {seen[number]}", text)
        seen[number] = text
    return sorted((number, Path(text)) for number, text in seen.items())
