"""svgf trace command: layers and headers, determinism, overwrite rules, errors, bundled data."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from tracescenes import read_exr

from svgf_cli.cli import main
from svgf_trace import render, tracing
from svgf_trace.animation import Animation
from svgf_trace.scene import load_obj

TESTDATA = Path(__file__).resolve().parent.parent / "testdata"
SCENE = str(TESTDATA / "cornell_checker.obj")
ANIM = str(TESTDATA / "anim.json")

INPUT_CHANNELS = {
    "R", "G", "B", "direct.R", "direct.G", "direct.B", "indirect.R", "indirect.G",
    "indirect.B", "emission.R", "emission.G", "emission.B", "albedo.R", "albedo.G",
    "albedo.B", "N.X", "N.Y", "N.Z", "Z", "P.X", "P.Y", "P.Z", "motion.X", "motion.Y", "id",
}  # fmt: skip
HALF_CHANNELS = {
    "R", "G", "B", "direct.R", "direct.G", "direct.B", "indirect.R", "indirect.G",
    "indirect.B", "emission.R", "emission.G", "emission.B",
}  # fmt: skip
REFERENCE_CHANNELS = {
    "R", "G", "B", "direct.R", "direct.G", "direct.B", "indirect.R", "indirect.G", "indirect.B",
}  # fmt: skip


def run(args: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    with pytest.raises(SystemExit) as info:
        main(["trace", *args])
    captured = capsys.readouterr()
    return int(info.value.code or 0), captured.out, captured.err


def small(out: str, *extra: str, resolution: str = "24x14") -> list[str]:
    return [SCENE, "-o", out, "--resolution", resolution, "--animation", ANIM, "--max-depth",
            "3", *extra]  # fmt: skip


def test_layers_headers_and_progress(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "seq" / "in.####.exr"
    ref = tmp_path / "seq" / "ref.####.exr"
    code, stdout, _ = run(small(str(out), "--frames", "2-3", "--reference", str(ref),
                                "--reference-spp", "8", resolution="64x36"), capsys)  # fmt: skip
    assert code == 0
    # One Deadline-style line per frame when stdout is not a terminal.
    assert "Progress: 50% (frame 2, 1/2," in stdout and "Progress: 100% (frame 3, 2/2," in stdout
    layers, spec = read_exr(tmp_path / "seq" / "in.0003.exr")
    assert set(layers) == INPUT_CHANNELS
    formats = {n: str(spec.channelformat(k)) for k, n in enumerate(spec.channelnames)}
    assert {n for n, f in formats.items() if f == "half"} == HALF_CHANNELS
    assert spec.getattribute("compression") == "piz"
    assert spec.getattribute("svgf/frame") == 3 and spec.getattribute("svgf/spp") == 1
    assert spec.getattribute("svgf/seed") == 0
    assert len(spec.getattribute("worldToCamera")) == 16
    # G-buffer sanity: unit normals facing the camera, ids of real objects, albedo in [0, 1].
    hit = layers["id"] >= 0
    normals = np.stack([layers["N.X"], layers["N.Y"], layers["N.Z"]], axis=-1)
    np.testing.assert_allclose(np.linalg.norm(normals[hit], axis=-1), 1.0, atol=1e-5)
    assert set(np.unique(layers["id"])) <= set(range(-1, 8))
    assert layers["albedo.R"].min() >= 0 and layers["albedo.R"].max() <= 1
    # The light is seen directly: its emission layer is Ke and it is in the direct layer.
    light = layers["id"] == 5
    assert light.any() and np.all(layers["emission.R"][light] == 17.0)
    assert np.all(layers["direct.R"][light] >= 17.0)
    reference, ref_spec = read_exr(tmp_path / "seq" / "ref.0003.exr")
    assert set(reference) == REFERENCE_CHANNELS
    assert {str(ref_spec.channelformat(k)) for k in range(ref_spec.nchannels)} == {"float"}
    assert ref_spec.getattribute("svgf/spp") == 8


def test_combined_is_direct_plus_indirect(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert run(small(str(tmp_path / "f.####.exr"), "--float"), capsys)[0] == 0
    layers, _ = read_exr(tmp_path / "f.0001.exr")
    for c in "RGB":
        assert np.array_equal(layers[c], layers[f"direct.{c}"] + layers[f"indirect.{c}"])
    assert layers["indirect.R"].max() > 0 and layers["direct.R"].max() > 0
    # Half radiance: the sum of the stored halves, rounded once more to half.
    assert run(small(str(tmp_path / "h.####.exr")), capsys)[0] == 0
    half, _ = read_exr(tmp_path / "h.0001.exr")
    for c in "RGB":
        total = (half[f"direct.{c}"] + half[f"indirect.{c}"]).astype(np.float16).astype(np.float32)
        assert np.array_equal(half[c], total)


def test_same_seed_gives_identical_files_whatever_the_range_or_threads(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    # Small chunks so the two-thread run really splits every batch across threads.
    monkeypatch.setattr(tracing, "MIN_RAYS_PER_THREAD", 7)
    assert run(small(str(tmp_path / "a.####.exr"), "--frames", "1-3", "--threads", "2"),
               capsys)[0] == 0  # fmt: skip
    assert run(small(str(tmp_path / "b.####.exr"), "--frames", "2", "--threads", "1"),
               capsys)[0] == 0  # fmt: skip
    assert (tmp_path / "a.0002.exr").read_bytes() == (tmp_path / "b.0002.exr").read_bytes()
    assert (tmp_path / "a.0001.exr").read_bytes() != (tmp_path / "a.0002.exr").read_bytes()
    # The optional layers too (lobes, motion to the next frame, gradient samples).
    extra = ("--lobes", "--motion-next", "--gradient-samples")
    assert run(small(str(tmp_path / "x.####.exr"), "--frames", "1-2", "--threads", "2",
                     *extra), capsys)[0] == 0  # fmt: skip
    assert run(small(str(tmp_path / "y.####.exr"), "--frames", "2", "--threads", "1", *extra),
               capsys)[0] == 0  # fmt: skip
    assert (tmp_path / "x.0002.exr").read_bytes() == (tmp_path / "y.0002.exr").read_bytes()
    assert run(small(str(tmp_path / "c.####.exr"), "--frames", "2", "--seed", "1"),
               capsys)[0] == 0  # fmt: skip
    seed0, _ = read_exr(tmp_path / "a.0002.exr")
    seed1, _ = read_exr(tmp_path / "c.0002.exr")
    assert not np.array_equal(seed0["R"], seed1["R"])
    assert np.array_equal(seed0["Z"], seed1["Z"])  # the G-buffer does not depend on the seed


def test_sampling_does_not_depend_on_batch_size(monkeypatch: pytest.MonkeyPatch) -> None:
    scene = load_obj(TESTDATA / "cornell.obj")
    results = []
    for batch_paths in (1 << 20, 100):
        monkeypatch.setattr(tracing, "MAX_PATHS_PER_BATCH", batch_paths)
        geo = render.prepare_frame(scene, Animation(), 1, 12, 8)
        hits = render.trace_primary(geo)
        results.append(render.trace_samples(geo, hits, 5, 4, render.frame_key(3, 1, 1)))
        geo.tracer.close()
    assert np.array_equal(results[0][0], results[1][0])
    assert np.array_equal(results[0][1], results[1][1])


def test_existing_output_needs_overwrite(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    target = tmp_path / "o.0001.exr"
    target.write_bytes(b"keep me")
    code, _, err = run(small(str(tmp_path / "o.####.exr")), capsys)
    assert code == 4 and "ERROR:" in err and "o.0001.exr" in err and "--overwrite" in err
    assert target.read_bytes() == b"keep me"
    assert run(small(str(tmp_path / "o.####.exr"), "--overwrite", "-q"), capsys)[0] == 0
    assert target.read_bytes()[:4] == b"\x76\x2f\x31\x01"  # the OpenEXR magic number


@pytest.mark.parametrize(
    ("args", "code", "message"),
    [
        (["missing.obj", "-o", "x.####.exr"], 3, "missing.obj: scene file not found"),
        ([SCENE, "-o", "x.####.exr", "--resolution", "big"], 2, "WIDTHxHEIGHT"),
        ([SCENE, "-o", "x.exr", "--frames", "1-2"], 2, "no frame token"),
        ([SCENE, "-o", "x.####.exr", "--frames", "1-3x0"], 2, "--frames"),
        ([SCENE, "-o", "x.####.exr", "--spp", "0"], 2, "'--spp': 0 is not in the range x>=1"),
        ([SCENE, "-o", "x.####.exr", "--animation", "nope.json"], 3, "nope.json"),
        ([SCENE, "-o", "x.####.exr", "--reference-half"], 2, "need --reference"),
        ([SCENE, "-o", "x.####.exr", "--skip-layer", "N"], 2, "--skip-layer"),
    ],
)
def test_bad_arguments_fail_with_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch,
    args: list[str], code: int, message: str,
) -> None:  # fmt: skip
    monkeypatch.chdir(tmp_path)
    got, _, err = run(args, capsys)
    assert got == code and message in err
    assert err.startswith("ERROR: ") and err.count("\n") == 1
    assert not list(tmp_path.glob("*.exr"))


def test_missing_texture_is_named(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    (tmp_path / "s.mtl").write_text("newmtl t\nmap_Kd wood.png\n")
    (tmp_path / "s.obj").write_text("mtllib s.mtl\nusemtl t\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    code, _, err = run([str(tmp_path / "s.obj"), "-o", str(tmp_path / "x.####.exr")], capsys)
    assert code == 3 and "texture not found" in err and "wood.png" in err
    assert not list(tmp_path.glob("*.exr"))


def test_bundled_sequence_is_complete_and_reproducible(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    seq = TESTDATA / "seq"
    inputs = sorted(seq.glob("in.*.exr"))
    refs = sorted(seq.glob("ref.*.exr"))
    assert [p.name for p in inputs] == [f"in.{f:04d}.exr" for f in range(1, 11)]
    assert [p.name for p in refs] == [f"ref.{f:04d}.exr" for f in range(1, 11)]
    assert sum(p.stat().st_size for p in inputs + refs) < 8 * 1024 * 1024
    bundled, spec = read_exr(seq / "in.0004.exr")
    assert set(bundled) == INPUT_CHANNELS and (spec.width, spec.height) == (128, 72)
    assert spec.getattribute("svgf/frame") == 4 and spec.getattribute("svgf/spp") == 1
    ref, ref_spec = read_exr(seq / "ref.0004.exr")
    assert set(ref) == REFERENCE_CHANNELS and ref_spec.getattribute("svgf/spp") == 1024
    # The documented command (testdata/README.md) reproduces the input frame. Embree picks
    # its SIMD kernels per CPU, so compare to float tolerance rather than bytes.
    code, _, _ = run([SCENE, "-o", str(tmp_path / "in.####.exr"), "--frames", "4",
                      "--resolution", "128x72", "--spp", "1", "--max-depth", "5", "--seed", "0",
                      "--animation", ANIM, "-q"], capsys)  # fmt: skip
    assert code == 0
    fresh, _ = read_exr(tmp_path / "in.0004.exr")
    for name in ("Z", "P.X", "N.Y", "albedo.G", "motion.X", "motion.Y", "id"):
        np.testing.assert_allclose(fresh[name], bundled[name], rtol=1e-4, atol=1e-4, err_msg=name)
    same = np.isclose(fresh["R"], bundled["R"], rtol=2e-3, atol=1e-3)
    assert same.mean() > 0.99


def test_slimmer_files_for_fixtures(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out, ref = tmp_path / "s.####.exr", tmp_path / "r.####.exr"
    code, _, _ = run(small(str(out), "--skip-layer", "P", "--skip-layer", "id", "--compression",
                           "zip", "--reference", str(ref), "--reference-spp", "4",
                           "--reference-channels", "rgb", "--reference-half"), capsys)  # fmt: skip
    assert code == 0
    layers, spec = read_exr(tmp_path / "s.0001.exr")
    assert set(layers) == INPUT_CHANNELS - {"P.X", "P.Y", "P.Z", "id"}
    assert spec.getattribute("compression") == "zip"
    reference, ref_spec = read_exr(tmp_path / "r.0001.exr")
    assert set(reference) == {"R", "G", "B"}
    assert {str(ref_spec.channelformat(k)) for k in range(3)} == {"half"}
    assert ref_spec.getattribute("compression") == "zip"


def test_a_supersampled_reference_averages_the_pixel(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Emission only (--max-depth 0: noise-free): the pixel-centre reference of the ceiling
    light is all or nothing per pixel; with --reference-supersample 2 the pixels its edge
    crosses take the covered share, and the light's total stays about the same."""
    refs = {}
    for k in (1, 2):
        code, _, _ = run(small(str(tmp_path / f"i{k}.####.exr"), "--frames", "1",
                               "--max-depth", "0", "--reference", str(tmp_path / f"r{k}.####.exr"),
                               "--reference-spp", "4", "--reference-supersample", str(k), "-q",
                               resolution="48x28"), capsys)  # fmt: skip
        assert code == 0
        refs[k] = read_exr(tmp_path / f"r{k}.0001.exr")
    centre, coarse_spec = refs[1]
    boxed, spec = refs[2]
    light = float(centre["R"].max())
    assert light > 1.0
    assert set(np.unique(centre["R"]).tolist()) <= {0.0, light}
    partial = (boxed["R"] > 0.05 * light) & (boxed["R"] < 0.95 * light)
    assert partial.sum() >= 4
    assert abs(float(boxed["R"].sum()) / float(centre["R"].sum()) - 1.0) < 0.3
    assert spec.getattribute("svgf/reference/supersample") == 2
    assert coarse_spec.getattribute("svgf/reference/supersample") is None


def test_jittered_samples_go_through_their_frames_positions(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """--jitter: each pixel's primary hit projects to the frame's own random position in the
    pixel (``render.pixel_jitter``), a new one every frame; without it, to the pixel centre.
    The header says so, and gradient samples (which re-trace pixel centres) refuse it."""
    scene = load_obj(Path(SCENE))
    anim = Animation()
    width, height = 20, 12
    positions = {}
    for jitter in (False, True):
        for frame in (1, 2):
            result, _ = render.render_frame(scene, anim, frame, width, height, 1, 1, 7,
                                            jitter=jitter)
            hit = np.isfinite(result.layers["Z"]) & (result.layers["Z"] > 0)
            assert hit.mean() > 0.2
            where = result.camera.project(result.layers["P"].astype(np.float64))
            grid = np.stack(np.meshgrid(np.arange(width), np.arange(height)), axis=-1)
            positions[jitter, frame] = np.where(hit[..., None], where - grid, np.nan)
    centre = positions[False, 1]
    np.testing.assert_allclose(centre[np.isfinite(centre)], 0.5, atol=2e-3)
    for frame in (1, 2):
        offsets = positions[True, frame]
        want = render.pixel_jitter(7, frame, width, height)
        seen = np.isfinite(offsets)
        np.testing.assert_allclose(offsets[seen], want[seen], atol=2e-3)
    assert np.nanmean(np.abs(positions[True, 1] - positions[True, 2])) > 0.2
    code, _, _ = run(small(str(tmp_path / "j.####.exr"), "--frames", "1", "--jitter", "-q"),
                     capsys)
    assert code == 0
    _, spec = read_exr(tmp_path / "j.0001.exr")
    assert spec.getattribute("svgf/jitter") == "box"
    code, _, err = run(small(str(tmp_path / "g.####.exr"), "--frames", "2", "--jitter",
                             "--gradient-samples"), capsys)
    assert code == 2 and "--jitter" in err
