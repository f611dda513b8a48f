"""`python -m svgf_cli.results`: see :mod:`svgf_cli.results`."""

from __future__ import annotations

import argparse
import os
import resource
import sys
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from svgf_cli.results.checks import all_checks
from svgf_cli.results.page import page, write_images
from svgf_cli.results.perceptual import jod_line
from svgf_cli.results.run import DenoiseRunner, SequenceRun, SubprocessDenoise, run_sequence
from svgf_cli.results.run import skipped_methods as find_skipped
from svgf_cli.results.table import METHODS, SEQUENCES, SVGF, MethodSpec, SequenceSpec

REPO = Path(__file__).resolve().parents[2]


def _named(items: Sequence[Any], names: Sequence[str], what: str) -> dict[str, Any]:
    """``items`` by name; the first unknown name in ``names`` is an error."""
    known = {item.name: item for item in items}
    unknown = [n for n in names if n not in known]
    if unknown:
        raise SystemExit(f"ERROR: unknown {what} {unknown[0]!r} (choose from {', '.join(known)})")
    return known


def select(
    only: Sequence[str] | None, method_names: Sequence[str] | None
) -> tuple[list[SequenceSpec], list[MethodSpec]]:
    """The sequences and methods named (all by default); unknown names are an error."""
    sequences = list(SEQUENCES)
    if only:
        known = _named(SEQUENCES, only, "sequence")
        sequences = [known[n] for n in only]
    methods = list(METHODS)
    if method_names:
        _named(METHODS, method_names, "method")
        methods = [m for m in METHODS if m.name in method_names or m.name == SVGF]
    return sequences, methods


def generate(
    docs: Path,
    sequences: Sequence[SequenceSpec],
    methods: Sequence[MethodSpec],
    runner: DenoiseRunner,
    frames: Sequence[int] | None = None,
    repo: Path = REPO,
    log=print,  # noqa: ANN001 - a print-like callable
) -> tuple[list[SequenceRun], list]:
    """Run everything and (re)write ``docs/results.md`` and ``docs/results/``.

    ``docs/results/`` is generated only: files there that this run did not write are removed.
    Returns the runs and the checks.
    """
    skipped = find_skipped(methods, runner)
    for name, reason in skipped.items():
        log(f"results: {name}: skipped: {reason}")
    runs = []
    with tempfile.TemporaryDirectory(prefix="svgf-results-") as tmp:
        for spec in sequences:
            log(f"results: {spec.folder}: denoise + evaluate")
            run = run_sequence(spec, methods, skipped, repo, Path(tmp), runner, frames)
            for note in run.notes:
                if note.status != "warned":
                    log(f"results: {spec.folder}: {note.method} {note.status}: {note.text}")
            runs.append(run)
    images = docs / "results"
    images.mkdir(parents=True, exist_ok=True)
    written = set()
    for run in runs:
        written.update(write_images(run, methods, images))
    for stale in sorted(images.iterdir()):
        if stale.is_file() and stale.name not in written:
            stale.unlink()
    from svgf_cli.results.perceptual import jod_checks

    checks = all_checks(runs) + jod_checks(runs)
    (docs / "results.md").write_text(page(runs, methods, skipped, checks), encoding="utf-8")
    return runs, checks


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m svgf_cli.results", description=(__doc__ or "").splitlines()[0]
    )
    parser.add_argument(
        "--docs",
        type=Path,
        default=REPO / "docs",
        help="where results.md and results/ go [default: docs]",
    )
    parser.add_argument(
        "--only",
        nargs="+",
        metavar="NAME",
        help="only these sequences (e.g. seq lag-shadow cycles-metal)",
    )
    parser.add_argument("--methods", metavar="A,B", help="only these methods (svgf always runs)")
    parser.add_argument("--frames", metavar="SPEC", help="only these frames (e.g. 1-4)")
    args = parser.parse_args(argv)

    from svgf_cli.io.patterns import parse_frame_spec

    frames = parse_frame_spec(args.frames) if args.frames else None
    sequences, methods = select(args.only, args.methods.split(",") if args.methods else None)
    start = time.perf_counter()
    runs, checks = generate(args.docs, sequences, methods, SubprocessDenoise(), frames)
    wall = time.perf_counter() - start
    usage = [resource.getrusage(who) for who in (resource.RUSAGE_SELF, resource.RUSAGE_CHILDREN)]
    cpu = sum(u.ru_utime + u.ru_stime for u in usage)
    print(f"results: wrote {args.docs / 'results.md'} and {args.docs / 'results'}/")
    for run in runs:
        denoise = sum(run.denoise_seconds.values())
        print(
            f"results: {run.spec.folder}: denoise {denoise:.1f} s "
            f"({len(run.denoise_seconds)} runs), evaluate {run.evaluate_seconds:.1f} s"
        )
    print(
        f"results: {wall:.0f} s wall, {cpu:.0f} s CPU (user + sys, this process and its "
        f"children) on {os.cpu_count()} logical cores"
    )
    print("ColorVideoVDP (JOD) and relMSE against OIDN, per sequence:")
    for run in runs:
        print("  " + jod_line(run))
    print("Issue targets:")
    for check in checks:
        print("  " + check.line())
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
