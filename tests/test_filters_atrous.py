"""The a-trous kernel against the float64 reference of the paper's equations 1-5.

The fast kernel is register-blocked, splits each row into tap-validity segments and gives
out-of-image taps weight 0 at the centre's address; the reference
(``reference_svgf.atrous_iteration``, shared with the whole-denoiser comparison) sums the
in-image taps of each pixel the obvious way, so every border, background and step case is
checked independently.
"""

from __future__ import annotations

import numpy as np
import pytest
import reference_svgf as ref

from svgf_cli.filters.atrous import atrous_iteration, luminance_stop_guides
from svgf_cli.filters.fastmath import REC709, fast_exp, fast_log2, fma

F32 = np.float32


def _scene(num_signals: int, height: int, width: int, seed: int) -> dict[str, np.ndarray]:
    """A sloped surface with a depth step, a normal crease, background columns and rows."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:height, 0:width].astype(np.float64)
    depth = 4.0 + 0.05 * x + 0.02 * y
    depth[:, width // 2:] += 1.5  # silhouette
    normal = np.zeros((3, height, width))
    normal[2] = -1.0
    normal[0, height // 2:] = 0.6  # crease
    normal /= np.linalg.norm(normal, axis=0)
    background = np.zeros((height, width), dtype=bool)
    background[:, :2] = True
    background[0] = True
    background[height - 2, width // 3] = True  # an isolated hole
    # Row ends: background at the right end of a row; a lone surface pixel at the right end
    # after a background gap; a row whose only surface pixel is its third.
    background[1, width - 2:] = True
    if width > 4:
        background[2, width - 2] = True
    if height > 9:
        background[9, 3:] = True
    depth[background] = 0.0
    normal[:, background] = 0.0
    ddx = np.gradient(depth, axis=1)
    ddy = np.gradient(depth, axis=0)
    illumination = rng.gamma(1.5, 0.7, (num_signals, 3, height, width))
    variance = rng.gamma(1.0, 0.3, (num_signals, height, width))
    # A noise-free patch: zero variance, so the luminance stop's floor (1e-5 l) decides.
    variance[:, 3:7, 2:6] = 0.0
    # Radiance-mode pixels (mode mask bits): a block in signal 0, scattered pixels in the
    # last signal, and a bit of an unrelated signal (2) that must not matter.
    mode = np.zeros((height, width), dtype=np.uint16)
    mode[2:6, 3:7] |= 1
    mode |= ((rng.uniform(size=(height, width)) < 0.15) << (num_signals - 1)).astype(np.uint16)
    mode[::3] |= 4
    return {
        "illumination": illumination.astype(F32), "variance": variance.astype(F32),
        "mode": mode, "depth": depth.astype(F32), "ddx": ddx.astype(F32),
        "ddy": ddy.astype(F32), "normal": normal.astype(F32),
    }


def _radiance_mode(mode: np.ndarray, num_signals: int, first: int = 0) -> np.ndarray:
    """(S, H, W) booleans: bit ``first + s`` of the mode mask (signal s filtered as radiance)."""
    return np.stack([(mode >> (first + s)) & 1 == 1 for s in range(num_signals)])


@pytest.mark.parametrize(
    ("num_signals", "step", "sigma_normal", "width"),
    [(2, 1, 128.0, 23), (2, 2, 128.0, 19), (1, 4, 128.0, 21), (2, 8, 64.0, 13),
     (1, 2, 100.0, 17), (2, 1, 1.0, 9), (3, 1, 128.0, 22), (3, 4, 64.0, 15)],
)
def test_atrous_iteration_matches_the_equations(
    num_signals: int, step: int, sigma_normal: float, width: int
) -> None:
    height = 14
    scene = _scene(num_signals, height, width, seed=step + width)
    luminance = np.empty((num_signals, height, width), dtype=F32)
    inverse_scale = np.empty_like(luminance)
    luminance_stop_guides(scene["illumination"], scene["variance"], scene["mode"], 0,
                          scene["depth"], F32(4.0), REC709, luminance, inverse_scale)
    out_c = np.full_like(scene["illumination"], np.nan)
    out_v = np.full_like(scene["variance"], np.nan)
    atrous_iteration(
        scene["illumination"], scene["variance"], luminance, inverse_scale, scene["depth"],
        scene["ddx"], scene["ddy"], scene["normal"], step, 1.0, sigma_normal, True, out_c,
        out_v,
    )
    # The stage alone: the reference filters with the kernel's guides (the luminance is the
    # guide's magnitude, the mode its sign).
    want_c, want_v = ref.atrous_iteration(
        scene["illumination"], scene["variance"], np.abs(luminance), luminance < 0,
        inverse_scale, scene["depth"], scene["ddx"], scene["ddy"], scene["normal"], step, 1.0,
        sigma_normal,
    )
    # The mode test matters here: without it the result moves by far more than the tolerance.
    mixed_c, _ = ref.atrous_iteration(
        scene["illumination"], scene["variance"], np.abs(luminance),
        np.zeros_like(luminance, dtype=bool), inverse_scale, scene["depth"], scene["ddx"],
        scene["ddy"], scene["normal"], step, 1.0, sigma_normal,
    )
    assert np.max(np.abs(mixed_c - want_c)) > 0.05
    # fast_exp (relative error 4e-6) and fast_log2 (absolute error 1e-6 on log2(cos), so up
    # to sigma_n ln2 1e-6 = 9e-5 relative on w_n at sigma_n = 128) set the tolerance.
    np.testing.assert_allclose(out_c, want_c, rtol=2e-4, atol=1e-6)
    np.testing.assert_allclose(out_v, want_v, rtol=4e-4, atol=1e-7)
    # Background keeps its value: outside a row's surface span it is copied, a hole inside
    # the span gets only its own centre weight (c h^2 / h^2, within an ulp).
    np.testing.assert_array_equal(out_c[..., :2], scene["illumination"][..., :2])
    np.testing.assert_array_equal(out_c[..., 0, :], scene["illumination"][..., 0, :])
    hole = (slice(None), slice(None), height - 2, width // 3)
    np.testing.assert_allclose(out_c[hole], scene["illumination"][hole], rtol=1e-6)


@pytest.mark.parametrize(("num_signals", "width", "sigmas"), [
    (2, 11, 4.0), (1, 7, 4.0), (2, 2, 4.0), (1, 1, 4.0), (3, 9, 4.0), (3, 8, (4.0, 1.0, 2.5)),
    (2, 5, (1.0, 4.0)),
])
def test_luminance_stop_guides_match_the_renormalised_gaussian(
    num_signals: int, width: int, sigmas: float | tuple[float, ...]
) -> None:
    height = 6
    scene = _scene(num_signals, height, max(width, 3), seed=width)
    scene = {k: np.ascontiguousarray(v[..., :width]) for k, v in scene.items()}
    luminance = np.empty((num_signals, height, width), dtype=F32)
    inverse_scale = np.empty_like(luminance)
    luminance_stop_guides(scene["illumination"], scene["variance"], scene["mode"], 0,
                          scene["depth"], sigmas, REC709, luminance, inverse_scale)
    radiance_mode = _radiance_mode(scene["mode"], num_signals)
    want_luminance, want_inverse_scale = ref.luminance_stop_guides(
        scene["illumination"], scene["variance"], scene["depth"], sigmas, ref.REC709)
    # The mode rides in the sign: radiance-mode guides are -(l + 1e-30), so even l = 0 is
    # negative there.
    assert np.all((luminance < 0) == radiance_mode)
    assert radiance_mode.any() or width < 7
    np.testing.assert_allclose(np.abs(luminance), want_luminance, rtol=1e-6)
    np.testing.assert_allclose(inverse_scale, want_inverse_scale, rtol=1e-5)
    # The inputs reach the renormalisation: without it (zero weight outside the image and on
    # background, no division) the scale would differ at borders and next to background.
    g = np.array([0.25, 0.5, 0.25])
    padded = np.pad(np.where(scene["depth"] > 0, scene["variance"], 0.0), ((0, 0), (1, 1), (1, 1)))
    plain = sum(g[i] * g[j] * padded[:, j:j + height, i:i + width]
                for j in range(3) for i in range(3))
    sigma = np.broadcast_to(np.asarray(sigmas, dtype=np.float64), (num_signals,))[:, None, None]
    unnormalised = 1.0 / (sigma * np.sqrt(plain + (1e-5 * want_luminance) ** 2))
    assert np.mean(np.abs(unnormalised / want_inverse_scale - 1.0) > 0.01) > 0.2
    # Where the variance is 0 the floor is relative to l (1e-5 l, so scaling the input
    # scales the output), not absolute: 1 / (4e-5 l), far from 1 / 4e-5 unless l = 1.
    flat = (slice(None), slice(4, 6), slice(3, 5))
    if width >= 5:
        np.testing.assert_allclose(want_inverse_scale[flat],
                                   1.0 / (1e-5 * sigma * want_luminance[flat]), rtol=1e-9)
        assert np.all(np.abs(want_luminance[flat] - 1.0) > 0.01)


@pytest.mark.parametrize(("num_signals", "width", "first"), [
    (1, 23, 0), (2, 11, 0), (3, 9, 0), (2, 5, 1), (1, 2, 0), (1, 1, 0), (3, 3, 0),
])
def test_blurred_luminance_guides_match_the_reference(num_signals: int, width: int,
                                                      first: int) -> None:
    """``luminance_guide_blur``: the guide is the 3x3 Gaussian of the luminance over the
    in-image surface pixels of the pixel's own mode; the inverse scale is unchanged but for
    its floor, which follows the guide."""
    height = 12
    scene = _scene(num_signals + first, height, max(width, 3), seed=width + first)
    scene = {k: np.ascontiguousarray(v[..., :width]) for k, v in scene.items()}
    signals = slice(first, first + num_signals)
    illumination = np.ascontiguousarray(scene["illumination"][signals])
    variance = np.ascontiguousarray(scene["variance"][signals])
    sigmas = (4.0, 1.0, 2.5)[:num_signals]
    luminance = np.empty((num_signals, height, width), dtype=F32)
    inverse_scale = np.empty_like(luminance)
    luminance_stop_guides(illumination, variance, scene["mode"], first, scene["depth"],
                          sigmas, REC709, luminance, inverse_scale, blur=True)
    radiance_mode = _radiance_mode(scene["mode"], num_signals, first)
    want_luminance, want_inverse_scale = ref.luminance_stop_guides(
        illumination, variance, scene["depth"], sigmas, ref.REC709, blur_modes=radiance_mode)
    assert np.all((luminance < 0) == radiance_mode)
    np.testing.assert_allclose(np.abs(luminance), want_luminance, rtol=1e-5, atol=1e-7)
    np.testing.assert_allclose(inverse_scale, want_inverse_scale, rtol=1e-5)
    if width < 5:
        return
    # The blur happened, and it kept to the pixel's mode: blurring across modes, or not at
    # all, gives other guides.
    plain, _ = ref.luminance_stop_guides(illumination, variance, scene["depth"], sigmas)
    across, _ = ref.luminance_stop_guides(illumination, variance, scene["depth"], sigmas,
                                          ref.REC709, blur_modes=np.zeros_like(radiance_mode))
    assert np.max(np.abs(np.abs(luminance) - plain)) > 0.1
    assert np.max(np.abs(np.abs(luminance) - across)) > 0.05


def _skewed_plane(seed: int) -> np.ndarray:
    """(1, 3, 64, 96) one-sample light of mean 1 on a flat plane: 0.25 on 80 % of the
    samples, 4 on the rest."""
    bright = np.random.default_rng(seed).uniform(size=(1, 1, 64, 96)) < 0.2
    return np.ascontiguousarray(np.broadcast_to(np.where(bright, 4.0, 0.25), (1, 3, 64, 96)),
                                dtype=F32)


def _mean_after_five_iterations(illumination: np.ndarray, variance: np.ndarray,
                                sigma: float, blur: bool, symmetric: bool = False) -> float:
    """The a-trous output's mean over the inside of a flat, facing plane (:func:`_skewed_plane`)
    after five iterations, as a share of the input's."""
    height, width = illumination.shape[2:]
    depth = np.full((height, width), 5.0, dtype=F32)
    zero = np.zeros_like(depth)
    normal = np.zeros((3, height, width), dtype=F32)
    normal[2] = -1.0
    mode = np.zeros((height, width), dtype=np.uint16)
    colour = illumination
    for iteration in range(5):
        guide = np.empty((1, height, width), dtype=F32)
        inverse_scale = np.empty_like(guide)
        luminance_stop_guides(colour, variance, mode, 0, depth, sigma, REC709, guide,
                              inverse_scale, blur=blur, symmetric=symmetric)
        out_c = np.empty_like(colour)
        out_v = np.empty_like(variance)
        atrous_iteration(colour, variance, guide, inverse_scale, depth, zero, zero, normal,
                         1 << iteration, 1.0, 128.0, True, out_c, out_v)
        colour, variance = out_c, out_v
    return float(colour[0, 1, 8:-8, 8:-8].mean() / illumination[0, 1, 8:-8, 8:-8].mean())


def test_the_blurred_guide_keeps_the_mean_of_one_sample_noise() -> None:
    """One-sample light is skewed (a few bright samples among dark ones): weighed by their
    own luminance the bright samples count less and the a-trous output is darker than its
    input; compared through 3x3 means it keeps far more of the mean. Five iterations of a
    flat, lit plane at the stops' default sigma_l."""
    illumination = _skewed_plane(7)
    variance = np.full((1, 64, 96), np.var(illumination[0, 0]), dtype=F32)
    sharp = _mean_after_five_iterations(illumination, variance, 2.0, blur=False)
    blurred = _mean_after_five_iterations(illumination, variance, 2.0, blur=True)
    assert sharp < 0.9  # measured 0.78
    assert abs(1.0 - blurred) < 0.5 * (1.0 - sharp)  # measured 0.97


@pytest.mark.parametrize(("step", "width", "symmetric"), [
    (1, 23, (True, False)), (2, 17, (False, True)), (4, 21, (True,)), (1, 22, (True, False, True)),
    (2, 15, (True, True, True)),
])
def test_symmetric_stops_match_the_equations(step: int, width: int,
                                             symmetric: tuple[bool, ...]) -> None:
    """A symmetric signal's plane holds -sqrt(inverse scale), and its taps are stopped at the
    product of both pixels' roots (``ref.atrous_iteration`` with ``symmetric``); the other
    signals of the group are filtered as without it, bit for bit."""
    num_signals, height = len(symmetric), 14
    scene = _scene(num_signals, height, width, seed=3 * step + width)
    # Deviations that differ from pixel to pixel by up to 30x: the two stops differ.
    scene["variance"] *= np.random.default_rng(width).uniform(0.03, 30.0, scene["variance"].shape
                                                             ).astype(F32)
    guides = {}
    for flags in (symmetric, (False,) * num_signals):
        luminance = np.empty((num_signals, height, width), dtype=F32)
        inverse_scale = np.empty_like(luminance)
        luminance_stop_guides(scene["illumination"], scene["variance"], scene["mode"], 0,
                              scene["depth"], F32(4.0), REC709, luminance, inverse_scale,
                              symmetric=flags)
        out_c = np.full_like(scene["illumination"], np.nan)
        out_v = np.full_like(scene["variance"], np.nan)
        atrous_iteration(scene["illumination"], scene["variance"], luminance, inverse_scale,
                         scene["depth"], scene["ddx"], scene["ddy"], scene["normal"], step,
                         1.0, 128.0, True, out_c, out_v)
        guides[flags] = (luminance, inverse_scale, out_c, out_v)
    luminance, roots, out_c, out_v = guides[symmetric]
    plain = guides[(False,) * num_signals]
    np.testing.assert_array_equal(luminance, plain[0])
    for s, flag in enumerate(symmetric):
        if flag:
            assert np.all(roots[s] < 0)
            np.testing.assert_allclose(roots[s] * roots[s], plain[1][s], rtol=1e-6)
            assert np.max(np.abs(out_c[s] - plain[2][s])) > 0.01  # the stop changed
        else:
            np.testing.assert_array_equal(roots[s], plain[1][s])
            np.testing.assert_array_equal(out_c[s], plain[2][s])
            np.testing.assert_array_equal(out_v[s], plain[3][s])
    want_c, want_v = ref.atrous_iteration(
        scene["illumination"], scene["variance"], np.abs(luminance), luminance < 0, plain[1],
        scene["depth"], scene["ddx"], scene["ddy"], scene["normal"], step, 1.0, 128.0,
        symmetric)
    np.testing.assert_allclose(out_c, want_c, rtol=2e-4, atol=1e-6)
    np.testing.assert_allclose(out_v, want_v, rtol=4e-4, atol=1e-7)


def test_the_symmetric_stop_keeps_the_mean_of_one_sample_noise() -> None:
    """Skewed one-sample light whose variance estimate follows each sample (a bright sample's
    own moments make its deviation large, a dim one's small, as a short history's do): with
    the centre's deviation alone a bright pixel's stop takes in its dim neighbours while
    theirs shut it out, and its light is lost; the symmetric stop weighs each pair alike.
    Five iterations of a flat plane, the guide blurred as in ``default``."""
    illumination = _skewed_plane(9)
    variance = np.ascontiguousarray(0.5 * illumination[:, 1] ** 2, dtype=F32)
    own = _mean_after_five_iterations(illumination, variance, 1.5, blur=True)
    symmetric = _mean_after_five_iterations(illumination, variance, 1.5, blur=True,
                                            symmetric=True)
    assert own < 0.95  # measured 0.83
    assert abs(1.0 - symmetric) < 0.5 * (1.0 - own)  # measured 0.98


@pytest.mark.parametrize(("step", "width"), [(1, 20), (2, 9)])
def test_three_signals_in_one_pass_equal_a_pair_and_a_single(step: int, width: int) -> None:
    """The triple loop shares only the geometric weights: each signal's result is the one
    the pair loop gives it, bit for bit (so grouping never changes an output)."""
    scene = _scene(3, 12, width, seed=step)
    sigmas = (4.0, 1.0, 4.0)
    luminance = np.empty((3, 12, width), dtype=F32)
    inverse_scale = np.empty_like(luminance)
    luminance_stop_guides(scene["illumination"], scene["variance"], scene["mode"], 0,
                          scene["depth"], sigmas, REC709, luminance, inverse_scale)
    geometry = (scene["depth"], scene["ddx"], scene["ddy"], scene["normal"], step, 1.0, 128.0,
                True)
    together_c = np.empty_like(scene["illumination"])
    together_v = np.empty_like(scene["variance"])
    atrous_iteration(scene["illumination"], scene["variance"], luminance, inverse_scale,
                     *geometry, together_c, together_v)
    apart_c = np.empty_like(together_c)
    apart_v = np.empty_like(together_v)
    for part in (slice(0, 2), slice(2, 3)):
        part_luminance = np.empty_like(luminance[part])
        part_inverse = np.empty_like(part_luminance)
        luminance_stop_guides(scene["illumination"][part], scene["variance"][part],
                              scene["mode"], part.start, scene["depth"], sigmas[part],
                              REC709, part_luminance, part_inverse)
        np.testing.assert_array_equal(part_luminance, luminance[part])
        np.testing.assert_array_equal(part_inverse, inverse_scale[part])
        atrous_iteration(scene["illumination"][part], scene["variance"][part], part_luminance,
                         part_inverse, *geometry, apart_c[part], apart_v[part])
    np.testing.assert_array_equal(together_c, apart_c)
    np.testing.assert_array_equal(together_v, apart_v)
    assert not np.array_equal(together_c[2], together_c[0])


def test_atrous_iteration_without_variance_leaves_it_alone_and_refuses_aliasing() -> None:
    scene = _scene(2, 10, 12, seed=1)
    luminance = np.empty((2, 10, 12), dtype=F32)
    inverse_scale = np.empty_like(luminance)
    luminance_stop_guides(scene["illumination"], scene["variance"], scene["mode"], 0,
                          scene["depth"], F32(4.0), REC709, luminance, inverse_scale)
    args = (luminance, inverse_scale, scene["depth"], scene["ddx"], scene["ddy"],
            scene["normal"], 1, 1.0, 128.0)
    out_c = np.empty_like(scene["illumination"])
    untouched = np.full_like(scene["variance"], 7.0)
    atrous_iteration(scene["illumination"], scene["variance"], *args, False, out_c, untouched)
    assert np.all(untouched == 7.0)
    with pytest.raises(ValueError, match="out_illumination overlaps illumination"):
        atrous_iteration(scene["illumination"], scene["variance"], *args, True,
                         scene["illumination"], untouched)
    with pytest.raises(ValueError, match="out_variance overlaps variance"):
        atrous_iteration(scene["illumination"], scene["variance"], *args, True, out_c,
                         scene["variance"])


def test_fast_log2_power_and_fma() -> None:
    from numba import njit

    @njit
    def evaluate(x: np.ndarray, exponent: np.float32) -> tuple[np.ndarray, np.ndarray]:
        log2 = np.empty_like(x)
        power = np.empty_like(x)
        for i in range(x.size):
            log2[i] = fast_log2(x[i])
            # cos ** sigma_n as the a-trous forms it inside its exponent.
            power[i] = fast_exp(exponent * fast_log2(x[i]) * F32(0.6931472)) if x[i] > 0 else 0.0
        return log2, power

    x = np.geomspace(1e-30, 1.0, 4001).astype(F32)
    log2, power = evaluate(x, F32(100.0))
    want_log2 = np.log2(x.astype(np.float64))
    assert np.all(np.abs(log2 - want_log2) < 1e-6 + 1.2e-7 * np.abs(want_log2))
    want = x.astype(np.float64) ** 100.0
    relative = np.abs(power - want) / np.maximum(want, 1e-300)
    # Near 1 (the weights that matter) 1e-4; down to fast_exp's flush (2**-50) still 2e-3,
    # and exactly 0 below it (no subnormal weights: fastmath._EXP2_FLUSH).
    assert np.max(relative[x > 0.8]) < 1e-4
    assert np.max(relative[want > 2e-15]) < 2e-3
    assert np.all(power[want < 5e-16] == 0.0)
    assert evaluate(np.array([0.0], dtype=F32), F32(3.0))[1][0] == 0.0

    @njit
    def fused(a: np.float32, b: np.float32, c: np.float32) -> np.float32:
        return fma(a, b, c)

    # 1 + 2^-23 squared is 1 + 2^-22 + 2^-46: one rounding keeps the 2^-46 a product-then-sum
    # would lose.
    a = F32(1.0 + 2.0**-23)
    assert fused(a, a, F32(-(1.0 + 2.0**-22))) == F32(2.0**-46)


def test_noalias_njit_marks_arrays_and_lets_a_many_array_loop_vectorize() -> None:
    """Guards the numba-internal hook behind noalias_njit (and its reason to exist)."""
    from svgf_cli.filters.noalias import noalias_njit

    def body(out: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray, d: np.ndarray,
             e: np.ndarray, f: np.ndarray, g: np.ndarray, h: np.ndarray) -> None:
        for i in range(out.size):
            out[i] = a[i] + b[i] * c[i] + d[i] * e[i] + f[i] * g[i] + h[i]

    kernel = noalias_njit(boundscheck=False, error_model="numpy")(body)
    arrays = [np.ones(64, dtype=F32) for _ in range(9)]
    kernel(*arrays)
    assert np.all(arrays[0] == 5.0)
    ir = next(iter(kernel.inspect_llvm().values()))
    definition = next(line for line in ir.splitlines() if line.startswith("define") and
                      "body" in line)
    assert definition.count("noalias") >= 9
    assert "x float>" in ir  # a vector loop exists



def test_guides_compile_once_for_one_sigma_or_one_per_signal() -> None:
    """One sigma for all signals and one per signal (a tuple, or an array numba may see
    read-only) reach the kernel as the same array type: one compiled signature, not one
    per way of passing them (each costs seconds of a clean clone's compile)."""
    from svgf_cli.filters import atrous

    scene = _scene(3, 6, 7, seed=3)
    luminance = np.empty((3, 6, 7), dtype=F32)
    inverse_scale = np.empty_like(luminance)
    read_only = np.array([4.0, 1.0, 2.5], dtype=F32)
    read_only.setflags(write=False)
    stops = np.array([True, False, True])
    stops.setflags(write=False)
    for sigmas, symmetric in ((2.0, False), ((4.0, 1.0, 2.5), (True, False, True)),
                              (read_only, stops)):
        luminance_stop_guides(scene["illumination"], scene["variance"], scene["mode"], 0,
                              scene["depth"], sigmas, REC709, luminance, inverse_scale,
                              symmetric=symmetric)
    kinds = {(str(s[5]), str(s[10])) for s in atrous._guide_rows.signatures}
    assert kinds == {("array(float32, 1d, C)", "array(bool, 1d, C)")}
