"""Run one sequence: every applicable method through the real `svgf denoise`, then one
`svgf evaluate` pass (in process) that scores them all with the baselines and the raw input.

`svgf denoise` runs as a child process (:class:`SubprocessDenoise`): the installed command,
exactly as a user runs it. Tests pass an in-process runner instead (same arguments).
"""

from __future__ import annotations

import importlib.util
import re
import subprocess
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Protocol

from svgf_cli.evaluate.engine import ContactFrame, EvaluationRequest, run_evaluation
from svgf_cli.evaluate.metrics import METRIC_KEYS
from svgf_cli.evaluate.report import EvaluationReport
from svgf_cli.filters.params import DEFAULT_PRESET, PRESETS
from svgf_cli.io.patterns import SequencePattern
from svgf_cli.results.table import (
    ANIMATION,
    INPUT,
    JOD_METHODS,
    OIDN,
    OIDN_NOPREFILTER,
    SVGF,
    MethodSpec,
    SequenceSpec,
)


@dataclass
class DenoiseOutcome:
    returncode: int
    stderr: str
    seconds: float = 0.0


class DenoiseRunner(Protocol):
    """How `svgf denoise` is run: its help text (to probe options) and a run."""

    def help_text(self) -> str: ...

    def denoise(self, args: Sequence[str]) -> DenoiseOutcome: ...


class SubprocessDenoise:
    """The installed `svgf denoise` of this interpreter, as a child process."""

    def __init__(self) -> None:
        self._help: str | None = None

    def help_text(self) -> str:
        if self._help is None:
            done = subprocess.run(
                [sys.executable, "-m", "svgf_cli", "denoise", "--help"],
                capture_output=True,
                text=True,
                check=True,
            )
            self._help = done.stdout
        return self._help

    def denoise(self, args: Sequence[str]) -> DenoiseOutcome:
        start = time.perf_counter()
        done = subprocess.run(
            [sys.executable, "-m", "svgf_cli", "denoise", *args],
            capture_output=True,
            text=True,
            check=False,
        )
        return DenoiseOutcome(done.returncode, done.stderr, time.perf_counter() - start)


def unknown_options(options: Sequence[str], help_text: str) -> list[str]:
    """The ``--long`` options in ``options`` that ``help_text`` does not name."""
    missing = []
    for option in options:
        name = option.split("=", 1)[0]
        if name.startswith("--") and not re.search(
            rf"(?<![\w-]){re.escape(name)}(?![\w-])", help_text
        ):
            missing.append(name)
    return missing


@dataclass
class MethodNote:
    """Why a method has no row on a sequence (or what it warned about)."""

    method: str
    status: str  # "skipped", "failed", "warned"
    text: str


@dataclass
class SequenceRun:
    """One sequence's report, contact frames and notes."""

    spec: SequenceSpec
    report: EvaluationReport
    contacts: list[ContactFrame]
    notes: list[MethodNote] = field(default_factory=list)
    denoise_seconds: dict[str, float] = field(default_factory=dict)
    evaluate_seconds: float = 0.0
    size: tuple[int, int] = (0, 0)  # width, height

    @property
    def names(self) -> list[str]:
        return [m.name for m in self.report.methods]


def _last_line(text: str) -> str:
    lines = [line.strip() for line in text.strip().splitlines() if line.strip()]
    return lines[-1] if lines else "(no message)"


def _warnings(text: str) -> list[str]:
    return [line.strip() for line in text.splitlines() if line.startswith("WARNING")]


def skipped_methods(methods: Sequence[MethodSpec], runner: DenoiseRunner) -> dict[str, str]:
    """``{name: reason}`` for the methods this installation cannot run at all."""
    reasons: dict[str, str] = {}
    help_text = None
    for method in methods:
        if method.baseline is None:
            help_text = help_text if help_text is not None else runner.help_text()
            missing = unknown_options(method.options, help_text)
            if missing:
                reasons[method.name] = (
                    f"`svgf denoise` has no {', '.join(f'`{m}`' for m in missing)} option yet"
                )
        elif method.baseline in (OIDN, OIDN_NOPREFILTER) and not _has("pyoidn"):
            reasons[method.name] = "pyoidn is not installed (pip install 'svgf[oidn]')"
    return reasons


def _has(module: str) -> bool:
    return importlib.util.find_spec(module) is not None


def jod_available() -> bool:
    """Whether cvvdp and torch can be imported (the ``perceptual`` extra is installed)."""
    try:
        return all(importlib.util.find_spec(m) is not None for m in ("torch", "pycvvdp"))
    except (ImportError, ValueError, AttributeError):  # a module set to None in sys.modules
        return False


def jod_request(names: Sequence[str]) -> list[str]:
    """The JOD methods among ``names`` (empty when the extra is missing)."""
    return [n for n in JOD_METHODS if n in names] if jod_available() else []


def run_sequence(
    spec: SequenceSpec,
    methods: Sequence[MethodSpec],
    skipped: dict[str, str],
    repo: Path,
    work: Path,
    runner: DenoiseRunner,
    frames: Sequence[int] | None = None,
) -> SequenceRun:
    """Denoise ``spec`` with every applicable method, then score them all in one pass."""
    folder = repo / spec.folder
    inputs = str(folder / spec.inputs)
    references = str(folder / spec.references)
    outputs, notes, seconds = _denoise_methods(spec, methods, skipped, inputs, work, runner,
                                               frames)  # fmt: skip
    if SVGF not in outputs:
        failed = next((n.text for n in notes if n.method == SVGF), "not run")
        raise RuntimeError(f"{spec.folder}: svgf denoise (default preset) failed: {failed}")

    baselines = [
        m.baseline
        for m in methods
        if m.baseline is not None and m.name not in skipped and m.applies_to(spec)
    ]
    contact_frames = [f for f in spec.contact_frames if frames is None or f in frames]
    scored = [SVGF, *[n for n in outputs if n != SVGF], *(b for b in baselines if b)]
    request = EvaluationRequest(
        output=outputs[SVGF],
        reference=references,
        input=inputs,
        frames=list(frames) if frames else None,
        baselines=tuple(b for b in baselines if b is not None),
        params=PRESETS[DEFAULT_PRESET],
        preset=DEFAULT_PRESET,
        layers=spec.aovs,
        contact_frames=contact_frames,
        compare=[(name, path) for name, path in outputs.items() if name != SVGF],
        jod=jod_request(scored),
        keep_displays=tuple(key for key, _ in ANIMATION),
    )
    start = time.perf_counter()
    report, contacts = run_evaluation(request)
    elapsed = time.perf_counter() - start
    _publishable(report, spec, methods, repo)
    from svgf_cli.io.exr import read_info

    info = read_info(SequencePattern.parse(references).path(report.frames[0]))
    return SequenceRun(spec, report, contacts, notes, seconds, elapsed, (info.width, info.height))


def _denoise_methods(
    spec: SequenceSpec,
    methods: Sequence[MethodSpec],
    skipped: dict[str, str],
    inputs: str,
    work: Path,
    runner: DenoiseRunner,
    frames: Sequence[int] | None,
) -> tuple[dict[str, str], list[MethodNote], dict[str, float]]:
    """Run `svgf denoise` for every applicable method that is not a baseline: the output
    pattern of each that succeeded, notes on failures and warnings, and the seconds each took."""
    notes: list[MethodNote] = []
    outputs: dict[str, str] = {}
    seconds: dict[str, float] = {}
    frame_args = ["--frames", ",".join(str(f) for f in frames)] if frames else []
    for method in methods:
        if method.baseline is not None or method.name in skipped:
            continue
        if not method.applies_to(spec):
            continue
        output = str(work / spec.name / method.name / "den.####.exr")
        args = [
            inputs,
            "-o",
            output,
            "--preset-aovs",
            spec.aovs,
            "--float",
            "--colour-only",
            "--quiet",
            *frame_args,
            *method.options,
        ]
        outcome = runner.denoise(args)
        seconds[method.name] = outcome.seconds
        if outcome.returncode != 0:
            status = "skipped" if outcome.returncode == 2 else "failed"
            notes.append(
                MethodNote(
                    method.name, status, f"exit {outcome.returncode}: {_last_line(outcome.stderr)}"
                )
            )
            continue
        warned = _warnings(outcome.stderr)
        if warned:
            notes.append(
                MethodNote(
                    method.name, "warned", f"{len(warned)} warning line(s), first: {warned[0]}"
                )
            )
        outputs[method.name] = output
    return outputs, notes, seconds


def _publishable(
    report: EvaluationReport, spec: SequenceSpec, methods: Sequence[MethodSpec], repo: Path
) -> None:
    """Replace temporary paths by the command that made each method (deterministic JSON)."""
    by_name = {m.name: m for m in methods}
    aovs = f" --preset-aovs {spec.aovs}" if spec.aovs != "svgf" else ""
    for method in report.methods:
        spec_method = by_name.get(method.name)
        if spec_method is not None and spec_method.baseline is None:
            method.source = f"{spec_method.command}{aovs}"
        if method.name == INPUT:
            method.source = str(Path(spec.folder) / spec.inputs)
        for score in method.frames:
            score.file = _relative(score.file, repo) if method.name == INPUT else None
    report.inputs = {
        "output": f"{by_name[SVGF].command}{aovs} (temporary files)",
        "reference": str(Path(spec.folder) / spec.references),
        "input": str(Path(spec.folder) / spec.inputs),
    }


def _relative(path: str | None, repo: Path) -> str | None:
    if path is None:
        return None
    try:
        return str(Path(path).resolve().relative_to(repo.resolve()))
    except ValueError:
        return path


def identical_methods(report: EvaluationReport) -> list[tuple[str, str]]:
    """Pairs of methods whose every per-frame value of every metric is equal."""
    pairs = []
    methods = report.methods
    for i, a in enumerate(methods):
        for b in methods[i + 1 :]:
            if len(a.frames) == len(b.frames) and all(
                fa.values.get(k) == fb.values.get(k)
                for fa, fb in zip(a.frames, b.frames, strict=True)
                for k in METRIC_KEYS
            ):
                pairs.append((a.name, b.name))
    return pairs


def frames_on_disk(spec: SequenceSpec, repo: Path) -> tuple[list[int], list[int]]:
    """The input and reference frame numbers of ``spec`` found on disk."""
    folder = repo / spec.folder
    inputs = SequencePattern.parse(str(folder / spec.inputs)).frames_on_disk()
    references = SequencePattern.parse(str(folder / spec.references)).frames_on_disk()
    return inputs, references
