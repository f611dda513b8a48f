"""`make demo`: trace a short sequence of the bundled Cornell box, denoise it, evaluate it.

Steps (each a subprocess of this Python, so it runs exactly what a user would type):

1. ``svgf trace testdata/cornell_checker.obj`` -> ``demo/in.####.exr`` (noisy 1 spp input)
   and ``demo/ref.####.exr`` (references);
2. ``svgf denoise demo/in.####.exr -o demo/den.####.exr``;
3. ``svgf evaluate`` of the denoised frames against the references;
4. a picture, ``demo/demo.png``: the last frame as noisy input | svgf | reference, labelled
   with that frame's relMSE and FLIP (the image in the README comes from here);
5. an animation, ``demo/demo.webp``: every frame as input | svgf | OIDN | reference (OIDN
   only where ``pyoidn`` is installed), tone-mapped like the picture, 8 frames a second:
   stills hide flicker. Written with Pillow; needs neither ffmpeg nor torch.

Run ``python -m svgf_cli.demo [--frames 1-24] [--resolution 320x180] [--reference-spp 64]
[--reference-supersample 4] [--out demo]``. Exits non-zero with an ``ERROR:`` line naming
the step that failed.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
TESTDATA = ROOT / "testdata"


def _run(step: str, args: list[str]) -> None:
    command = [sys.executable, "-m", "svgf_cli", *args]
    print(f"\n== {step}: svgf {' '.join(args)}", flush=True)
    start = time.perf_counter()
    code = subprocess.call(command)
    if code != 0:
        print(f"ERROR: demo step '{step}' failed with exit code {code}", file=sys.stderr)
        sys.exit(code)
    print(f"-- {step} done in {time.perf_counter() - start:.1f} s", flush=True)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description="Trace, denoise and evaluate a demo sequence.")
    parser.add_argument("--frames", default="1-24")
    parser.add_argument("--resolution", default="320x180")
    parser.add_argument("--reference-spp", default="64")
    # References averaged over 4x4 positions per pixel, as a production renderer's pixel
    # filter averages (svgf trace's default samples the pixel centre, like the input).
    parser.add_argument("--reference-supersample", default="4")
    parser.add_argument("--out", default="demo")
    args = parser.parse_args(argv)
    scene = TESTDATA / "cornell_checker.obj"
    animation = TESTDATA / "anim.json"
    if not scene.is_file() or not animation.is_file():
        print(f"ERROR: {scene} or {animation} is missing (run testdata/make_cornell.py)",
              file=sys.stderr)  # fmt: skip
        return 3
    out = Path(args.out)
    noisy = str(out / "in.####.exr")
    reference = str(out / "ref.####.exr")
    denoised = str(out / "den.####.exr")

    _run("trace", [
        "trace", str(scene), "-o", noisy, "--frames", args.frames,
        "--resolution", args.resolution, "--spp", "1", "--max-depth", "5", "--seed", "0",
        "--animation", str(animation), "--reference", reference,
        "--reference-spp", args.reference_spp,
        "--reference-supersample", args.reference_supersample, "--overwrite",
    ])  # fmt: skip
    _run("denoise", ["denoise", noisy, "-o", denoised, "--overwrite"])
    _run("evaluate", ["evaluate", denoised, "--reference", reference, "--input", noisy])
    picture = out / "demo.png"
    write_picture(noisy, denoised, reference, picture)
    animation = out / "demo.webp"
    shown = write_animation(noisy, denoised, reference, animation)

    print(f"\nDemo outputs in {out.resolve()}/:")
    print(f"  {noisy}      noisy 1-spp input with its G-buffer")
    print(f"  {denoised}     SVGF-denoised frames")
    print(f"  {reference}     converged references ({args.reference_spp} spp over "
          f"{args.reference_supersample}x{args.reference_supersample} positions per pixel)")
    print(f"\nPicture (input | svgf | reference): {picture.resolve()}")
    print(f"Animation ({' | '.join(shown)}): {animation.resolve()}")
    return 0


def write_picture(noisy: str, denoised: str, reference: str, path: Path) -> None:
    """The last frame side by side (input | svgf | reference), labelled with its metrics."""
    from svgf_cli.evaluate.contact import write_contact_sheet
    from svgf_cli.evaluate.engine import EvaluationRequest, resolve_frames, run_evaluation
    from svgf_cli.io.patterns import SequencePattern

    last = resolve_frames(SequencePattern.parse(denoised), denoised, None)[-1]
    request = EvaluationRequest(
        output=denoised, reference=reference, input=noisy, frames=[last], contact_frames=[last]
    )
    report, contacts = run_evaluation(request)
    write_contact_sheet(report, contacts, path, error_map=False, dpi=100)


def write_animation(noisy: str, denoised: str, reference: str, path: Path) -> list[str]:
    """Every frame as input | svgf | OIDN | reference (OIDN when pyoidn is installed), an
    animated WebP or GIF (by ``path``'s extension); returns the panel labels."""
    import importlib.util

    from svgf_cli.evaluate.animation import Panel
    from svgf_cli.evaluate.animation import write_animation as write
    from svgf_cli.evaluate.engine import EvaluationRequest, run_evaluation

    oidn = importlib.util.find_spec("pyoidn") is not None
    columns = [("input", "input (1 spp)"), ("svgf", "svgf"),
               *([("oidn", "OIDN")] if oidn else []), ("reference", "reference")]  # fmt: skip
    request = EvaluationRequest(output=denoised, reference=reference, input=noisy,
                                baselines=("oidn",) if oidn else (),
                                keep_displays=tuple(key for key, _ in columns))  # fmt: skip
    report, _ = run_evaluation(request)
    panels = [Panel(label, report.displays[key]) for key, label in columns]
    write(panels, path, scale=1, frame_numbers=report.frames)
    return [label for _, label in columns]


if __name__ == "__main__":
    sys.exit(main())
