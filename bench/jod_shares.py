"""Where svgf loses JOD, by cause: video JOD of svgf's output with one region (or frames)
replaced by the reference, per bundled sequence (issue 29).

    nice -n 10 .venv/bin/python bench/jod_shares.py [NAME ...]   # seq lag-shadow cycles-roll ...
    nice -n 10 .venv/bin/python bench/jod_shares.py --floor seq '/tmp/floor/ref.####.exr'

``--floor NAME PATTERN``: the reference floor instead: a second, independently seeded
reference of the sequence (``svgf trace --seed 1 ... --reference PATTERN``, docs/stability.md)
scored against the bundled one: video and still JOD, temporal error and relMSE (trimmed).

Per sequence: svgf (default preset, causal, in memory with its debug layers) and OIDN per frame
(prefiltered aux on Cycles), then svgf with each region swapped for the reference in linear
radiance before the tone map. ``gain`` = JOD(swapped) - JOD(svgf); ``share`` = gain / (10 -
JOD(svgf)), the part of svgf's whole deficit that region holds (shares need not add up: JOD is
not additive). Regions, from the input's G-buffer and svgf's own layers:

* edges: depth (relative step > 5 %), normal (cosine < 0.9) or mesh-id discontinuities to a
  4-neighbour, dilated by 1 px;
* disocclusions: surface pixels whose history length (min over signals, ``--debug-aovs``)
  is 1 (this frame's sample only; 0 marks no surface), from the second frame on;
* glossy: pixels where glossy/transmission signals carry > 25 % of the radiance (lobe inputs);
* interiors: every pixel that is none of the above;
* cold start: frames 1-4, whole frames.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

SEQUENCES = {
    "seq": ("testdata/seq", "svgf"),
    "lag-light_slide_dim": ("testdata/lag/light_slide_dim", "svgf"),
    "lag-light_step": ("testdata/lag/light_step", "svgf"),
    "lag-shadow": ("testdata/lag/shadow", "svgf"),
    "lag-camera": ("testdata/lag/camera", "svgf"),
    "lag-glossy": ("testdata/lag/glossy", "svgf"),
    "cycles-roll": ("testdata/cycles/roll", "cycles"),
    "cycles-metal": ("testdata/cycles/metal", "cycles"),
}
COLD_FRAMES = 4


def edges(frame) -> np.ndarray:  # noqa: ANN001 - svgf_cli.frame.Frame
    """Depth/normal/id discontinuities to a 4-neighbour, dilated by 1 px."""
    depth, normal, ids = frame.depth[0] if frame.depth.ndim == 3 else frame.depth, \
        frame.normal, frame.mesh_id[0] if frame.mesh_id.ndim == 3 else frame.mesh_id
    mask = np.zeros(depth.shape, bool)
    for axis in (0, 1):
        d0, d1 = depth, np.roll(depth, -1, axis)
        step = np.abs(d1 - d0) > 0.05 * np.maximum(np.minimum(np.abs(d0), np.abs(d1)), 1e-6)
        other = np.roll(normal, -1, axis + 1)
        cos = np.sum(normal * other, axis=0)
        # A zero normal is no surface (background, lights): its border is an id change.
        both = (np.sum(normal * normal, axis=0) > 0.25) & (np.sum(other * other, axis=0) > 0.25)
        edge = step | ((cos < 0.9) & both) | (ids != np.roll(ids, -1, axis))
        if axis == 0:
            edge[-1, :] = False
        else:
            edge[:, -1] = False
        mask |= edge | np.roll(edge, 1, axis)
    grown = mask.copy()
    for axis in (0, 1):
        grown |= np.roll(mask, 1, axis) | np.roll(mask, -1, axis)
    return grown


def glossy(frame) -> np.ndarray:  # noqa: ANN001
    lum = np.array([0.2126, 0.7152, 0.0722], np.float32)[:, None, None]
    total = np.sum(frame.total_radiance() * lum, axis=0)
    gloss = sum((np.sum(s.radiance * lum, axis=0) for s in frame.signals if s.glossy),
                np.zeros_like(total))  # fmt: skip
    return gloss > 0.25 * np.maximum(total, 1e-6)


def run(name: str) -> list[tuple[str, float, float]]:
    from svgf_cli.evaluate.baselines import make_method
    from svgf_cli.evaluate.metrics import tone_map
    from svgf_cli.evaluate.perceptual import jod_scores, load_metric
    from svgf_cli.filters.denoiser import Denoiser
    from svgf_cli.filters.params import PRESETS
    from svgf_cli.io.exr import fix_signal_set, read_frame, read_rgb
    from svgf_cli.io.layers import build_mapping
    from svgf_cli.io.patterns import SequencePattern

    folder, aovs = SEQUENCES[name]
    inputs = SequencePattern.parse(str(REPO / folder / "in.####.exr"))
    refs = SequencePattern.parse(str(REPO / folder / "ref.####.exr"))
    numbers = inputs.frames_on_disk()
    mapping, _ = fix_signal_set(inputs.path(numbers[0]), build_mapping(aovs))
    denoiser = Denoiser(PRESETS["default"], debug_layers=True)
    oidn = make_method("oidn", PRESETS["default"], layers=aovs)
    out, ref, oidn_out, masks = [], [], [], {"edges": [], "disocclusions": [], "glossy": []}
    for index, number in enumerate(numbers):
        frame = read_frame(inputs.path(number), mapping).frame
        result = denoiser.process(frame)
        out.append(np.asarray(result.color, np.float32))
        ref.append(read_rgb(refs.path(number), mapping)[0])
        oidn_out.append(oidn.process(frame))
        lengths = [v for k, v in result.layers.items() if k.startswith("history_length.")]
        history = np.min(np.stack(lengths), axis=0) if lengths else np.full(ref[-1].shape[1:], 9)
        masks["edges"].append(edges(frame))
        # 1 = a surface sample with no history (0 = no surface: background, lights)
        masks["disocclusions"].append((history > 0.5) & (history < 1.5) & (index > 0))
        masks["glossy"].append(glossy(frame))
    masks["interiors"] = [~(e | d | g) for e, d, g in
                          zip(masks["edges"], masks["disocclusions"], masks["glossy"],
                              strict=True)]  # fmt: skip
    masks["cold start"] = [np.full(m.shape, i < COLD_FRAMES) for i, m in
                           enumerate(masks["edges"])]  # fmt: skip
    metric = load_metric()
    ref_d = [tone_map(r) for r in ref]

    def jod(images: list[np.ndarray]) -> float:
        return jod_scores([tone_map(i) for i in images], ref_d, metric, stills=False).video

    base = jod(out)
    rows = [("svgf", base, 0.0), ("oidn", jod(oidn_out), 0.0)]
    for region, per_frame in masks.items():
        swapped = [np.where(m[None], r, o) for o, r, m in zip(out, ref, per_frame, strict=True)]
        area = float(np.mean([m.mean() for m in per_frame]))
        rows.append((region, jod(swapped), area))
    return rows


def floor(name: str, pattern: str) -> None:
    """Print the metrics of an independent reference against the sequence's reference."""
    from svgf_cli.evaluate import metrics
    from svgf_cli.evaluate.perceptual import jod_scores, load_metric
    from svgf_cli.io.exr import read_rgb
    from svgf_cli.io.layers import build_mapping
    from svgf_cli.io.patterns import SequencePattern

    folder, aovs = SEQUENCES[name]
    refs = SequencePattern.parse(str(REPO / folder / "ref.####.exr"))
    other = SequencePattern.parse(pattern)
    mapping = build_mapping(aovs)
    numbers = [n for n in refs.frames_on_disk() if other.path(n).is_file()]
    a = [read_rgb(refs.path(n), mapping)[0] for n in numbers]
    b = [read_rgb(other.path(n), mapping)[0] for n in numbers]
    da, db = [metrics.tone_map(x) for x in a], [metrics.tone_map(x) for x in b]
    score = jod_scores(db, da, load_metric())
    temporal = [metrics.temporal_error(db[i], db[i - 1], da[i], da[i - 1])
                for i in range(1, len(numbers))]  # fmt: skip
    relmse = [metrics.relmse_trimmed(y, x) for x, y in zip(a, b, strict=True)]
    print(f"{name} floor ({len(numbers)} frames): video JOD {score.video:.3f}, still JOD "
          f"{score.still:.3f}, temporal error {np.mean(temporal):.5f}, relMSE (trimmed) "
          f"{np.mean(relmse):.6f}")


def main(argv: list[str]) -> int:
    if argv[:1] == ["--floor"]:
        floor(argv[1], argv[2])
        return 0
    names = argv or list(SEQUENCES)
    for name in names:
        rows = run(name)
        base = rows[0][1]
        print(f"\n{name}: svgf video JOD {base:.3f}, OIDN {rows[1][1]:.3f}")
        print("| region | area | JOD with it = reference | gain | share of svgf's deficit |")
        print("|---|---|---|---|---|")
        for region, value, area in rows[2:]:
            gain = value - base
            share = gain / (10.0 - base) if base < 10.0 else 0.0
            print(f"| {region} | {area:.1%} | {value:.3f} | {gain:+.3f} | {share:.0%} |")
        sys.stdout.flush()
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
