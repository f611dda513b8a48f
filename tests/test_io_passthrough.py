"""The output is a drop-in replacement for its input: every part, channel, pixel type,
window, tile layout, line order, codec and attribute as read; only the colour changes.

Each test builds a tiny two-frame sequence with one real-world structure, denoises it with
the CLI, and compares the output with the input channel by channel and attribute by
attribute (`exr_fixtures.assert_passthrough`).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import OpenEXR
import pytest
from exr_fixtures import (
    H,
    PartSpec,
    W,
    assert_passthrough,
    bits_equal,
    box,
    gbuffer,
    read_parts,
    write_parts,
)
from test_cli_support import run_cli

from svgf_cli.io.exr import read_frame, read_rgb
from svgf_cli.io.layers import build_mapping

FRAMES = (1, 2)
RGB = {"R", "G", "B"}


def denoise(folder: Path, capsys: pytest.CaptureFixture[str], *options: str) -> Path:
    out = folder / "out"
    code, stdout, err = run_cli(
        ["denoise", folder / "in.####.exr", "-o", out / "o.####.exr", *options], capsys
    )
    assert code == 0, err
    denoise.stdout = stdout  # type: ignore[attr-defined]
    return out


def sequence(folder: Path, make_parts) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    for frame in FRAMES:
        write_parts(folder / f"in.{frame:04d}.exr", make_parts(frame))
    return folder


def check_all(folder: Path, out: Path, **expected) -> None:
    for frame in FRAMES:
        assert_passthrough(
            folder / f"in.{frame:04d}.exr", out / f"o.{frame:04d}.exr", **expected
        )


def test_overscan_negative_data_window_origin(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Data window larger than the display window, with a negative origin."""
    header = {"dataWindow": box(-3, -2, W, H), "displayWindow": box(0, 0, W - 6, H - 4)}
    folder = sequence(tmp_path, lambda f: [PartSpec(gbuffer(f), header=header)])
    out = denoise(folder, capsys)
    check_all(folder, out, changed={"": RGB})
    (_, out_header, _), = read_parts(out / "o.0002.exr")
    assert out_header["dataWindow"][0].tolist() == [-3, -2]


def test_region_render_data_window_inside_display(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    header = {"dataWindow": box(5, 4, W, H), "displayWindow": box(0, 0, W + 20, H + 10)}
    folder = sequence(tmp_path, lambda f: [PartSpec(gbuffer(f), header=header)])
    out = denoise(folder, capsys)
    check_all(folder, out, changed={"": RGB})


CRYPTO_ATTRIBUTES = {
    "cryptomatte/0a1b2c3/name": "CryptoObject",
    "cryptomatte/0a1b2c3/hash": "MurmurHash3_32",
    "cryptomatte/0a1b2c3/conversion": "uint32_to_float32",
    "cryptomatte/0a1b2c3/manifest": json.dumps({"sphere": "3f800000", "floor": "c2d8a000"}),
}


def crypto_layer(frame: int, height: int, width: int) -> dict[str, np.ndarray]:
    """Cryptomatte-style rank/coverage pairs: ids are float32 bit patterns of hashes (any
    bits at all, NaN payloads and denormals included), so only a bit-exact copy is right."""
    rng = np.random.default_rng(frame)
    layer = {}
    for rank in ("00", "01"):
        ids = rng.integers(0, 2**32, (height, width), dtype=np.uint64).astype(np.uint32)
        ids[0, 0] = 0x7FC12345  # a NaN with a payload
        ids[0, 1] = 0x00000001  # a denormal
        layer[f"CryptoObject{rank}.R"] = ids.view(np.float32)
        layer[f"CryptoObject{rank}.G"] = rng.uniform(0, 1, (height, width)).astype(np.float32)
        layer[f"CryptoObject{rank}.B"] = ids[::-1].copy().view(np.float32)
        layer[f"CryptoObject{rank}.A"] = rng.uniform(0, 1, (height, width)).astype(np.float32)
    return layer


def multipart(frame: int) -> list[PartSpec]:
    data = gbuffer(frame)
    beauty = {c: data.pop(c).astype(np.float16) for c in "RGB"}
    beauty["A"] = np.linspace(0.1, 0.9, W * H, dtype=np.float32).reshape(H, W).astype(np.float16)
    data["id"] = data["id"].astype(np.uint32)
    crypto_window = box(2, 1, W - 4, H - 3)  # a part with its own, smaller data window
    return [
        PartSpec(beauty, "beauty", {"view_note": "main"}),
        PartSpec(data, "gbuffer", {"compression": OpenEXR.PIZ_COMPRESSION}),
        PartSpec(
            crypto_layer(frame, H - 3, W - 4),
            "crypto",
            {**CRYPTO_ATTRIBUTES, "dataWindow": crypto_window, "displayWindow": box(0, 0, W, H)},
        ),
    ]


def test_multipart_cryptomatte_and_part_names(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    folder = sequence(tmp_path, multipart)
    out = denoise(folder, capsys)
    check_all(folder, out, changed={"beauty": RGB})
    parts = read_parts(out / "o.0001.exr")
    assert [p[0] for p in parts] == ["beauty", "gbuffer", "crypto"]
    beauty_header, gbuffer_header, crypto_header = (p[1] for p in parts)
    assert beauty_header["svgf/kind"] == "denoised" and "svgf/kind" not in crypto_header
    assert gbuffer_header["compression"] == OpenEXR.PIZ_COMPRESSION
    assert parts[0][2]["R"].dtype == np.float16  # the input colour's type is kept
    for key, value in CRYPTO_ATTRIBUTES.items():
        assert crypto_header[key] == value


def test_colour_only_writes_the_colour_part_and_its_alpha(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    folder = sequence(tmp_path, multipart)
    out = denoise(folder, capsys, "--colour-only")
    (name, header, pixels), = read_parts(out / "o.0002.exr")
    assert name == "beauty" and set(pixels) == {"R", "G", "B", "A"}
    (_, _, source), *_ = read_parts(folder / "in.0002.exr")
    assert bits_equal(pixels["A"], source["A"])
    assert header["view_note"] == "main"


def test_tiled_input_keeps_tiles_and_line_order(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    tiles = OpenEXR.TileDescription()
    tiles.xSize, tiles.ySize = 4, 4
    tiles.mode, tiles.roundingMode = OpenEXR.ONE_LEVEL, OpenEXR.ROUND_DOWN

    def parts(frame: int) -> list[PartSpec]:
        header = {
            "type": OpenEXR.tiledimage,
            "tiles": tiles,
            "lineOrder": OpenEXR.RANDOM_Y,
            "compression": OpenEXR.PIZ_COMPRESSION,
        }
        return [PartSpec(gbuffer(frame), header=header)]

    folder = sequence(tmp_path, parts)
    out = denoise(folder, capsys)
    check_all(folder, out, changed={"": RGB})
    (_, header, _), = read_parts(out / "o.0001.exr")
    assert header["type"] == OpenEXR.tiledimage
    assert (header["tiles"].xSize, header["tiles"].ySize) == (4, 4)


def test_decreasing_line_order_scanlines(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    header = {"lineOrder": OpenEXR.DECREASING_Y, "compression": OpenEXR.ZIPS_COMPRESSION}
    folder = sequence(tmp_path, lambda f: [PartSpec(gbuffer(f), header=header)])
    out = denoise(folder, capsys)
    check_all(folder, out, changed={"": RGB})


def mixed_types(frame: int) -> list[PartSpec]:
    channels: dict[str, np.ndarray] = dict(gbuffer(frame))
    for c in "RGB":
        channels[c] = channels[c].astype(np.float16)
    channels["A"] = np.full((H, W), 0.25, np.float16)  # an alpha that is not 1
    channels["A"][2, 3] = 0.0
    channels["id"] = channels["id"].astype(np.uint32)
    channels["mask.X"] = (np.arange(W * H, dtype=np.uint32).reshape(H, W) * 7919) | 2**31
    channels["spec.R"] = np.full((H, W), 70000.0, np.float32)  # beyond half, passed through
    return [PartSpec(channels, header={"compression": OpenEXR.ZIPS_COMPRESSION})]


def test_mixed_half_float_uint_channels_and_alpha(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    folder = sequence(tmp_path, mixed_types)
    out = denoise(folder, capsys)
    check_all(folder, out, changed={"": RGB})
    (_, _, pixels), = read_parts(out / "o.0002.exr")
    assert pixels["R"].dtype == np.float16 and pixels["mask.X"].dtype == np.uint32
    assert pixels["A"][0, 0] == np.float16(0.25) and pixels["A"][2, 3] == 0


def test_float_option_makes_only_the_colour_float(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    folder = sequence(tmp_path, mixed_types)
    out = denoise(folder, capsys, "--float")
    (_, _, pixels), = read_parts(out / "o.0001.exr")
    assert {pixels[c].dtype for c in "RGB"} == {np.dtype(np.float32)}
    assert pixels["A"].dtype == np.float16 and pixels["id"].dtype == np.uint32


ACESCG = (0.713, 0.293, 0.165, 0.830, 0.128, 0.044, 0.32168, 0.33767)
AP0 = (0.7347, 0.2653, 0.0, 1.0, 0.0001, -0.077, 0.32168, 0.33767)


def test_chromaticities_pass_through_and_set_luminance_weights(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """An ACEScg file is filtered with ACEScg luminance weights: the CLI's output is
    bit-identical to a direct Denoiser run on frames carrying those weights and differs
    from one with Rec.709 weights; the start-up log names them."""
    from svgf_cli.filters.denoiser import Denoiser
    from svgf_cli.filters.params import resolve_params

    header = {"chromaticities": ACESCG, "adoptedNeutral": (0.32168, 0.33767)}
    folder = sequence(tmp_path, lambda f: [PartSpec(gbuffer(f), header=header)])
    result = read_frame(folder / "in.0001.exr", build_mapping())
    acescg = (0.2722, 0.6741, 0.0537)
    assert np.allclose(result.luminance_weights.weights, acescg, atol=1e-4)
    assert result.frame.luminance_weights == result.luminance_weights.weights
    # Causal (no warm start), so that the Denoiser below is the whole run.
    out = denoise(folder, capsys, "--warm-start", "0")
    assert "luminance weights R 0.2722, G 0.6741, B 0.0537" in denoise.stdout
    check_all(folder, out, changed={"": RGB})
    (_, header_out, _), = read_parts(out / "o.0001.exr")
    assert np.allclose(header_out["chromaticities"], ACESCG)

    def direct(weights: tuple[float, float, float] | None) -> np.ndarray:
        denoiser = Denoiser(resolve_params(warm_start=0))  # the settings the CLI ran
        for frame in FRAMES:
            read = read_frame(folder / f"in.{frame:04d}.exr", build_mapping()).frame
            if weights is not None:
                read.luminance_weights = weights
            colour = denoiser.process(read).color
        return colour

    (_, _, pixels), = read_parts(out / f"o.{FRAMES[-1]:04d}.exr")
    written = np.stack([pixels[c] for c in "RGB"])
    assert written.dtype == np.float32
    assert bits_equal(written, direct(None))
    assert not np.array_equal(written, direct((0.2126, 0.7152, 0.0722)))


def test_negative_luminance_weight_is_dropped_for_the_filter(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """ACES2065-1 (AP0) has a negative blue weight: the filter gets the non-negative variant
    (``Frame.validate`` refuses a negative weight) and the log says so."""
    folder = sequence(tmp_path, lambda f: [PartSpec(gbuffer(f), header={"chromaticities": AP0})])
    result = read_frame(folder / "in.0001.exr", build_mapping())
    r, g, b = result.frame.luminance_weights
    assert b == 0.0 and r > 0.3 and g > 0.6 and abs(r + g - 1.0) < 1e-9
    assert result.luminance_weights.weights[2] < -0.07  # the file's own row, for reports
    denoise(folder, capsys)
    assert "B -0.0721" in denoise.stdout
    assert f"the filter uses R {r:.4f}, G {g:.4f}, B 0.0000" in denoise.stdout


def test_debug_layers_never_collide_with_input_layers(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    def parts(frame: int) -> list[PartSpec]:
        channels = dict(gbuffer(frame))
        channels["variance.color"] = np.full((H, W), 0.5, np.float32)  # an input AOV
        channels["history_length.color"] = np.full((H, W), 3.0, np.float32)
        return [PartSpec(channels)]

    folder = sequence(tmp_path, parts)
    out = denoise(folder, capsys, "--debug-aovs")
    added = {"svgf.variance.color", "svgf.history_length.color", "svgf.color.R"}
    (_, _, pixels), = read_parts(out / "o.0002.exr")
    assert added <= set(pixels)
    debug = {n for n in pixels if n.startswith("svgf.")}
    check_all(folder, out, changed={"": RGB}, added={"": debug})
    assert np.all(pixels["variance.color"] == 0.5) and np.all(pixels["history_length.color"] == 3)


def cycles_frame(frame: int, *, reference: bool = False) -> list[PartSpec]:
    """Blender 4.5 multilayer names: ViewLayer.<pass>.<channel>, Combined next to Noisy
    Image, world-space Normal next to camera-space Denoising Normal, 1e10 background."""
    data = gbuffer(frame)
    v = "ViewLayer."
    channels: dict[str, np.ndarray] = {}
    for c in "RGB":
        channels[f"{v}Combined.{c}"] = data[c] * (0.5 if not reference else 1.0)
        if not reference:
            channels[f"{v}Noisy Image.{c}"] = data[c]
            channels[f"{v}Denoising Albedo.{c}"] = data[f"albedo.{c}"]
    channels[f"{v}Combined.A"] = np.ones((H, W), np.float32)
    if reference:
        return [PartSpec(channels)]
    channels[f"{v}Noisy Image.A"] = np.ones((H, W), np.float32)
    for c, world, camera in zip("XYZ", (0.0, 0.0, 1.0), (0.0, 1.0, 0.0), strict=True):
        channels[f"{v}Normal.{c}"] = np.full((H, W), world, np.float32)
        channels[f"{v}Denoising Normal.{c}"] = np.full((H, W), camera, np.float32)
    depth = data["Z"].copy()
    depth[0, :] = 1e10  # Cycles' background depth
    channels[f"{v}Depth.Z"] = depth
    for c, plane in zip("XYZW", (-data["motion.X"], data["motion.Y"], data["motion.X"],
                                 data["motion.Y"]), strict=True):
        channels[f"{v}Vector.{c}"] = np.ascontiguousarray(plane)
    channels[f"{v}IndexOB.X"] = data["id"]
    return [PartSpec(channels, header={"Software": "Blender 4.5.3"})]


def test_cycles_output_under_combined_and_evaluate_reads_it(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    folder = sequence(tmp_path, cycles_frame)
    for frame in FRAMES:
        write_parts(folder / f"ref.{frame:04d}.exr", cycles_frame(frame, reference=True))
    result = read_frame(folder / "in.0001.exr", build_mapping("cycles"))
    assert result.resolved["normal"] == tuple(f"ViewLayer.Normal.{c}" for c in "XYZ")
    assert result.frame.depth[0].max() == 0 and result.frame.depth[1].min() > 0  # 1e10: bg
    assert result.colour_channels == tuple(f"ViewLayer.Combined.{c}" for c in "RGB")
    out = denoise(folder, capsys, "--preset-aovs", "cycles")
    combined = {f"ViewLayer.Combined.{c}" for c in "RGB"}
    check_all(folder, out, changed={"": combined})  # Noisy Image is passed through
    (_, header, _), = read_parts(out / "o.0001.exr")
    assert header["Software"] == "Blender 4.5.3; svgf 0.1.0"
    colour, _ = read_rgb(out / "o.0001.exr", build_mapping("cycles"))
    assert colour.shape == (3, H, W)
    code, stdout, err = run_cli(
        [
            "evaluate",
            out / "o.####.exr",
            "--reference",
            folder / "ref.####.exr",
            "--preset-aovs",
            "cycles",
            "-q",
        ],
        capsys,
    )
    assert code == 0, err
    assert "svgf" in stdout


def test_input_without_colour_layer_gets_rgb_in_the_signals_part(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    def parts(frame: int) -> list[PartSpec]:
        data = gbuffer(frame)
        colour = {c: data.pop(c) for c in "RGB"}
        light = {f"{s}.{c}": colour[c] * k for c in "RGB" for s, k in
                 (("direct", 0.7), ("indirect", 0.3))}
        return [PartSpec({"Z": data.pop("Z")}, "depth"), PartSpec({**data, **light}, "light")]

    folder = sequence(tmp_path, parts)
    out = denoise(folder, capsys)
    check_all(folder, out, added={"light": RGB})
    (_, _, depth_part), (_, _, light_part) = read_parts(out / "o.0001.exr")
    assert light_part["R"].dtype == np.float16 and "R" not in depth_part


@pytest.mark.parametrize("codec", ["ZSTD_COMPRESSION", "HTJ2K256_COMPRESSION", "RLE_COMPRESSION"])
def test_codecs_without_an_option_name_are_kept(
    codec: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    header = {"compression": getattr(OpenEXR, codec)}
    try:
        folder = sequence(tmp_path, lambda f: [PartSpec(gbuffer(f), header=header)])
    except Exception as exc:  # an OpenEXR build without this codec
        pytest.skip(f"{codec} not available: {exc}")
    out = denoise(folder, capsys)
    check_all(folder, out, changed={"": RGB})
    (_, header_out, _), = read_parts(out / "o.0001.exr")
    assert header_out["compression"] == getattr(OpenEXR, codec)


def test_codecs_without_a_short_name_keep_distinct_names() -> None:
    # HTJ2K and ZSTD (OpenEXR 3.4) are kept as read; their names appear in notes and must not
    # collapse into one another.
    import OpenEXR

    from svgf_cli.io.output import codec_name

    htj2k = codec_name({"compression": OpenEXR.HTJ2K256_COMPRESSION})
    zstd = codec_name({"compression": OpenEXR.ZSTD_COMPRESSION})
    assert "htj2k256" in htj2k and "zstd" in zstd
    assert codec_name({"compression": OpenEXR.DWAB_COMPRESSION}) == "dwab"


def test_half_output_clamps_only_the_values_beyond_its_range() -> None:
    from svgf_cli.io.output import HALF_MAX, prepare_colour

    colour = np.array([[[1e6, -1e6, 0.25, -0.5, np.inf, 65504.0]]], np.float32)
    prepared = prepare_colour(colour, half=True)
    assert prepared.planes.dtype == np.float16
    assert prepared.planes.ravel().tolist() == [HALF_MAX, -HALF_MAX, 0.25, -0.5, 0.0, 65504.0]
    assert (prepared.nonfinite, prepared.clamped) == (1, 2)


def test_colour_only_keeps_the_colour_alpha_when_split_signals_are_filtered(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # direct + indirect are the filtered signals; the beauty R,G,B,A is the layer the
    # denoised colour replaces, so --colour-only writes it with its own alpha.
    def parts(frame: int) -> list[PartSpec]:
        data = gbuffer(frame)
        for c in "RGB":
            data[f"direct.{c}"] = 0.7 * data[c]
            data[f"indirect.{c}"] = 0.3 * data[c]
        data["A"] = np.linspace(0.2, 0.8, W * H, dtype=np.float32).reshape(H, W)
        return [PartSpec(data)]

    folder = sequence(tmp_path, parts)
    out = denoise(folder, capsys, "--colour-only")
    (_, _, pixels), = read_parts(out / "o.0002.exr")
    assert set(pixels) == {"R", "G", "B", "A"}
    (_, _, source), = read_parts(folder / "in.0002.exr")
    assert bits_equal(pixels["A"], source["A"])
