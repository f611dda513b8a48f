"""Issue 29 in `make results`: ColorVideoVDP (JOD) per sequence, its checks, the animations.

JOD needs the optional ``perceptual`` extra (cvvdp + torch; ``make results`` installs it).
Without it the JOD columns are empty, the page says why and the JOD checks are SKIP; the
animations need only Pillow.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from svgf_cli.results.checks import FAIL, PASS, SKIP, Check, _verdict
from svgf_cli.results.run import SequenceRun, jod_available
from svgf_cli.results.table import ANIMATION, JOD_METHODS, OIDN, SVGF

JOD_MARGIN = 0.3  # issue 29: svgf's video JOD at least OIDN's + this
RELMSE = "relmse_trimmed"


def write_animation(run: SequenceRun, images: Path) -> str | None:
    """``<name>_anim.webp``: input | svgf | OIDN | reference, every evaluated frame; the
    file's name, or None when the run kept no display frames."""
    from svgf_cli.evaluate.animation import Panel
    from svgf_cli.evaluate.animation import write_animation as write

    shown = run.report.displays
    panels = [Panel(label, shown[key]) for key, label in ANIMATION if key in shown]
    if len(panels) < 2:
        return None
    path = images / f"{run.spec.name}_anim.webp"
    write(panels, path, scale=2, frame_numbers=run.report.frames)
    return path.name


def _jod(run: SequenceRun, name: str, which: str) -> float | None:
    score = run.report.jod.get(name)
    return None if score is None else getattr(score, which)


def _f(value: float | None) -> str:
    return "–" if value is None else f"{value:.2f}"


def jod_table(runs: Sequence[SequenceRun]) -> str:
    """Markdown: per sequence, video and still JOD of every JOD method, and the verdicts."""
    names = [n for n in JOD_METHODS if any(n in run.report.jod for run in runs)]
    if not names:
        reason = "not measured: " + ("no JOD method ran" if jod_available() else
                                     "cvvdp/torch are not installed (pip install "
                                     "'svgf[perceptual]'; `make results` installs them)")
        return f"ColorVideoVDP {reason}."
    header = ["sequence", *(f"`{n}` video / still" for n in names),
              f"svgf video ≥ OIDN + {JOD_MARGIN}", "svgf relMSE ≤ OIDN"]  # fmt: skip
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for run in runs:
        cells = [f"`{run.spec.folder}`"]
        cells += [f"{_f(_jod(run, n, 'video'))} / {_f(_jod(run, n, 'still'))}" for n in names]
        cells += [_margin(run)[0], _relmse(run)[0]]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def _margin(run: SequenceRun) -> tuple[str, bool | None]:
    mine, theirs = _jod(run, SVGF, "video"), _jod(run, OIDN, "video")
    if mine is None or theirs is None:
        return "–", None
    ok = mine >= theirs + JOD_MARGIN
    return f"{'yes' if ok else 'no'} ({mine - theirs:+.2f})", ok


def _relmse(run: SequenceRun) -> tuple[str, bool | None]:
    names = run.names
    if SVGF not in names or OIDN not in names:
        return "–", None
    mine = run.report.method(SVGF).summary(RELMSE)
    theirs = run.report.method(OIDN).summary(RELMSE)
    if mine is None or theirs is None:
        return "–", None
    ok = mine <= theirs
    return f"{'yes' if ok else 'no'} ({mine / theirs:.2f}x)", ok


def check_jod_margin(runs: Sequence[SequenceRun]) -> Check:
    target = (f"svgf's video JOD >= OIDN's + {JOD_MARGIN} on every sequence (Cycles: OIDN "
              "with the aux prefilter)")  # fmt: skip
    results = [(run.spec.name, *_margin(run)) for run in runs]
    known = [r for r in results if r[2] is not None]
    if not known:
        return Check(29, target, SKIP, "JOD not measured (pip install 'svgf[perceptual]')")
    numbers = "; ".join(
        f"{name} svgf {_f(_jod(run, SVGF, 'video'))} vs OIDN {_f(_jod(run, OIDN, 'video'))}"
        for (name, _, ok), run in zip(results, runs, strict=True) if ok is not None
    )
    return Check(29, target, _verdict([bool(r[2]) for r in known]), numbers)


def check_relmse_vs_oidn(runs: Sequence[SequenceRun]) -> Check:
    target = "svgf's relMSE (trimmed) <= OIDN's on every sequence (Cycles: OIDN prefiltered)"
    results = [(run.spec.name, *_relmse(run)) for run in runs]
    known = [r for r in results if r[2] is not None]
    if not known:
        return Check(29, target, SKIP, "no OIDN numbers (pip install 'svgf[oidn]')")
    numbers = "svgf / OIDN: " + "; ".join(f"{name} {text.split(' ', 1)[1].strip('()')}"
                                          for name, text, _ in known)  # fmt: skip
    return Check(29, target, PASS if all(r[2] for r in known) else FAIL, numbers)


def jod_checks(runs: Sequence[SequenceRun]) -> list[Check]:
    return [check_jod_margin(runs), check_relmse_vs_oidn(runs)]


def jod_line(run: SequenceRun) -> str:
    """One printed line: video / still JOD of svgf and OIDN and the two issue-29 verdicts."""
    parts = [f"{n} {_f(_jod(run, n, 'video'))} / {_f(_jod(run, n, 'still'))}"
             for n in JOD_METHODS if n in run.report.jod]  # fmt: skip
    jod = ", ".join(parts) if parts else "JOD not measured"
    return (f"{run.spec.name}: video / still JOD: {jod}; svgf video >= OIDN + {JOD_MARGIN}: "
            f"{_margin(run)[0]}; svgf relMSE <= OIDN: {_relmse(run)[0]}")
