"""Bidirectional temporal accumulation: combine a forward and a time-reversed pass.

Offline, frame ``t`` can use the frames after it too. A forward pass (the causal SVGF) and a
reverse pass (the same filter run over the frames in reverse order, motion pointing to the
next frame) each reproject their own history at ``t``, with their own geometric tests,
modes and anti-lag, which shortens a side's history where it disagrees with frame ``t``.
Each pass keeps its accumulation unfiltered as its colour history where pixels move (a
causal run keeps the output of its feedback a-trous iteration): the combination below weighs
a side as an average of its effective samples, which a spatially filtered history is not,
and the feedback blur would compound with the resampling in both passes (measured on the
bundled sequences: relMSE 0.70-1.01x of forward-only with unfiltered histories against
0.79-1.16x with filtered ones). Where a pixel stands still (motion below ``STATIC_MOTION``)
the history keeps a share ``STATIC_FILTERED_SHARE`` (0.3) of the first a-trous iteration's
output (``filters.feedback.blend_history``): without resampling, a little recursive spatial
filtering pays, and more so as the image grows (unfiltered, ``lag/shadow`` at 256x144 was
worse than forward-only on FLIP, 1.06x; with the share 0.95x, relMSE 0.77x instead of
0.95x; at 128x72 ``lag/light_step`` 0.66x instead of 0.74x, ``lag/shadow`` 0.68x instead
of 0.70x; a share of 0.5 gains more at 256x144, 0.75x, but loses ``lag/shadow`` at
128x72, 0.71x; 1.0 loses both, 0.78x and 0.83x; 0.5 on moving pixels too: ``seq`` 0.72x
instead of 0.66x, ``lag/camera`` 0.76x instead of 0.64x, ``cycles/metal`` RMSE 1.0007x).

Before either pass blends frame ``t`` in, the two resampled histories go through a
consistency test (:func:`consistent_lengths`) and are combined with the current sample,
counted once, per signal and pixel:

* **consistency**: where both sides have history and their first moments differ by more
  than ``CONSISTENCY_SIGMA`` standard errors of the difference (per-sample variance ``v``,
  the larger of the two sides' ``m2 - m1^2``: a light switched, a shadow or highlight
  moved on one side only), the current sample decides which side to trust: with the
  log-likelihood ratio ``L = ((l - m_r)^2 - (l - m_f)^2) / (2 v)`` of the current
  luminance ``l`` the less likely side keeps ``1 - t |tanh(L / 2)|`` of its effective
  count, ``t`` the share of the disagreement beyond the noise. Continuous: sides within the
  noise, or a frame that cannot tell them apart, change nothing. Each side's anti-lag has
  compared it with the frame over a 10x10 window already; this compares the two sides
  pixel by pixel, which is far more sensitive (each is an average of several frames), and
  needs the frame only to break the tie;

* a side's history of length ``h`` (0: none) is an average of ``n(h)`` effective samples:
  the accumulation's blend schedule ``a_k = max(alpha, 1/k)`` gives the variance share
  ``v_1 = 1``, ``v_k = (1 - a_k)^2 v_(k-1) + a_k^2`` after ``k`` frames, and ``n(k) = 1/v_k``
  (``k`` for ``k <= 1/alpha``, tending to ``(2 - alpha)/alpha``); ``n(0) = 0`` and a
  fractional ``h`` (bilinear resampling, anti-lag) interpolates linearly between whole
  counts. Colour counts use ``alpha``, moment counts ``moments_alpha``;
* the combination is the inverse-variance average
  ``c = (x + n_f H_f + n_r H_r) / (1 + n_f + n_r)`` for the colour (``x`` this frame's
  demodulated value) and likewise for the luminance moments ``(l, l^2)``;
* its history length is ``1 + h_f + h_r`` (the frames it holds), which steers the variance
  estimate (temporal where it is >= 4) as a pass's own length does; background pixels get 0
  and their current values;
* SVGF's a-trous stops at the per-sample luminance variance ``m2 - m1^2``, tuned for a
  causal history of at most ``n_ref = n(history_cap)`` samples (9 at moments alpha 0.2).
  Where the combination holds more (``N = 1 + n_f + n_r > n_ref``), its colour is that
  much cleaner, so its variance is scaled by ``n_ref / N``
  (``m2 = m1^2 + min(1, n_ref / N) (m2 - m1^2)``): the spatial filter blurs as much
  relative to the remaining noise as it does on a long causal history, not more.
  (Measured on the bundled sequences: relMSE 1-7 % lower than without the scaling.)
  A glossy signal's ``n_ref`` is ``GLOSSY_REFERENCE_COUNT`` (3): its reflections carry
  detail the geometric guides do not see (a highlight a few pixels wide), which a cleaner
  combination can keep. Measured against 9: ``cycles/metal`` relMSE 0.82x of forward-only
  instead of 0.99x and RMSE 0.97x instead of 1.002x; ``lag/glossy`` at 256x144 RMSE 0.988x
  instead of 1.001x (temporal error 0.919x instead of 0.913x); ``lag/glossy`` and
  ``cycles/roll`` otherwise within 0.005. (3 for every
  signal gains more at 128x72, ``lag/camera`` 0.56x, but loses at 256x144, ``lag/shadow``
  1.02x instead of 0.95x: not kept.)

Each pass's anti-lag tests its history against the frame at ``PASS_ANTILAG_SIGMA_SCALE``
(6/7: 3.0 standard errors for the default 3.5) of ``antilag_sigma``. A false alarm costs a
causal run its history (the frame alone is left); in a bidirectional pass the other side
refills it, while a missed change (a light switched, a highlight moved) keeps a residual of
the old lighting in that side, which the combination carries into the frames around the
change (on ``lag/light_step`` the reverse side of frames 1-5 held 5.18 frames on average
where at most 4 agree with them; 4.81 at 3.0). Measured against 3.5 on the bundled
sequences: relMSE 3-8 % lower on five, within 0.3 % on ``seq``, ``lag/camera`` and
``cycles/roll``; temporal error at most 2 % higher (``lag/shadow`` 0.75x -> 0.76x); at
256x144 ``lag/camera`` relMSE 0.64x instead of 0.65x and ``lag/shadow`` 0.945x instead of
0.957x. 2.75 and 2.5 gain a little more relMSE (up to 3 % and 6 %) but raise
``lag/shadow``'s temporal error to 0.79x and 0.82x of forward-only.

The forward pass's histories are needed by the reverse pass in reverse order, so a run
spills them (``pack_history`` / ``unpack_history``: colour, first moment and the moments'
standard deviation as half floats, each plane scaled by its own maximum so that neither
exposure nor fireflies leave the half range; the history length as float32).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit, prange

from svgf_cli.filters.fastmath import FASTMATH, fast_exp, luminance
from svgf_cli.halfconv import to_half

F32 = np.float32
_ZERO = F32(0.0)
_ONE = F32(1.0)
# A packed plane's largest magnitude maps here: a quarter of the half range (65504).
HALF_TARGET = 16384.0
# Standard errors of the two sides' difference beyond which they disagree (consistency).
CONSISTENCY_SIGMA = 6.0
# A glossy signal's n_ref: the effective sample count up to which its combination's variance
# is given to the a-trous unscaled (other signals: n(history_cap); module docstring).
GLOSSY_REFERENCE_COUNT = 3.0
# A pass of a bidirectional run tests its history against the frame (anti-lag) at this share
# of the causal significance ``antilag_sigma`` (module docstring).
PASS_ANTILAG_SIGMA_SCALE = 6.0 / 7.0
# Share of the first a-trous iteration's output in a pass's colour history where the pixel
# does not move, and the motion (pixels, each axis) below which it does not (module docstring).
STATIC_FILTERED_SHARE = 0.3
STATIC_MOTION = 1e-3

_JIT = dict(fastmath=FASTMATH, cache=True, nogil=True, boundscheck=False, error_model="numpy")


def effective_counts(alpha: float, cap: int) -> np.ndarray:
    """``n(k)`` for k = 0 .. cap (float32): the effective sample count of an accumulation
    of ``k`` frames under the blend schedule ``a_k = max(alpha, 1/k)`` (module docstring)."""
    counts = np.zeros(cap + 1, dtype=np.float64)
    share = 1.0
    for k in range(1, cap + 1):
        a = max(alpha, 1.0 / k)
        share = (1.0 - a) ** 2 * share + a * a
        counts[k] = 1.0 / share
    return counts.astype(F32)


@dataclass
class SideHistory:
    """One pass's history at a frame, resampled at the frame's pixels after anti-lag and
    before the blend: per signal the colour (S, 3, H, W), the luminance moments
    (S, 2, H, W) and the history length (S, H, W), 0 where the pass has none. With
    ``temporal_albedo`` also the running mean (U, 3, H, W) over the pass's frames and this
    one of each of the U distinct demodulation colours, and its length (U, H, W)
    (``filters.albedo_history``)."""

    colour: np.ndarray
    moments: np.ndarray
    length: np.ndarray
    albedo: np.ndarray | None = None
    albedo_length: np.ndarray | None = None


@njit(inline="always", **_JIT)
def effective_count_at(table: np.ndarray, h: np.float32) -> np.float32:
    """``n(h)``: linear between whole counts, 0 at h <= 0, the last entry beyond the table."""
    last = table.shape[0] - 1
    hh = min(max(h, _ZERO), F32(last))
    below = min(np.int64(hh), last - 1) if last > 0 else np.int64(0)
    frac = hh - F32(below)
    upper = min(below + 1, last)
    return table[below] + frac * (table[upper] - table[below])


@njit(inline="always", **_JIT)
def _side_weights(
    table: np.ndarray, hf: np.float32, hr: np.float32, surface: bool,
) -> tuple[np.float32, np.float32, np.float32]:
    """``(n_f, n_r, 1) / (1 + n_f + n_r)`` with ``n = n(h)`` of ``table`` (0 off surfaces)."""
    nf = effective_count_at(table, hf) if surface else _ZERO
    nr = effective_count_at(table, hr) if surface else _ZERO
    inv = _ONE / (_ONE + nf + nr)
    return nf * inv, nr * inv, inv


@njit(parallel=True, **_JIT)
def combine_histories(
    current: np.ndarray,
    reverse_colour: np.ndarray,
    reverse_moments: np.ndarray,
    reverse_length: np.ndarray,
    depth: np.ndarray,
    colour_counts: np.ndarray,
    moment_counts: np.ndarray,
    luminance_weights: tuple[np.float32, np.float32, np.float32],
    reference_counts: np.ndarray,
    colour: np.ndarray,
    moments: np.ndarray,
    length: np.ndarray,
) -> None:
    """The combined accumulation of frame ``t`` (module docstring), in place.

    ``current`` is this frame's demodulated illumination (S, 3, H, W); ``colour``,
    ``moments`` and ``length`` hold the forward history (:class:`SideHistory` planes) and
    receive the combination (a run keeps no second copy); the reverse history is given as
    its three planes. ``colour_counts`` and ``moment_counts`` are :func:`effective_counts`
    tables for ``alpha`` and ``moments_alpha``, ``reference_counts`` (S,) is ``n_ref`` per
    signal. Writes
    ``c = (x + n_f H_f + n_r H_r) / (1 + n_f + n_r)`` per colour channel and moment, the
    moments' variance scaled by ``min(1, n_ref / N)``, and the length ``1 + h_f + h_r``;
    background: the current values and length 0.
    """
    num_signals = current.shape[0]
    height, width = depth.shape
    for y in prange(height):
        z = depth[y]
        wf = np.empty(width, dtype=np.float32)
        wr = np.empty(width, dtype=np.float32)
        wx = np.empty(width, dtype=np.float32)
        mf = np.empty(width, dtype=np.float32)
        mr = np.empty(width, dtype=np.float32)
        mx = np.empty(width, dtype=np.float32)
        for s in range(num_signals):
            # Both weight sets first: the forward length is overwritten by the combined one.
            h_row = length[s, y]
            hr_row = reverse_length[s, y]
            for x in range(width):
                hf = h_row[x]
                hr = hr_row[x]
                surface = z[x] > _ZERO
                wf[x], wr[x], wx[x] = _side_weights(colour_counts, hf, hr, surface)
                mf[x], mr[x], mx[x] = _side_weights(moment_counts, hf, hr, surface)
                h_row[x] = (_ONE + max(hf, _ZERO) + max(hr, _ZERO)) if surface else _ZERO
            for c in range(3):
                x_row = current[s, c, y]
                r_row = reverse_colour[s, c, y]
                out = colour[s, c, y]
                for x in range(width):
                    out[x] = wx[x] * x_row[x] + wf[x] * out[x] + wr[x] * r_row[x]
            r = current[s, 0, y]
            g = current[s, 1, y]
            b = current[s, 2, y]
            m1 = moments[s, 0, y]
            m2 = moments[s, 1, y]
            r1, r2 = reverse_moments[s, 0, y], reverse_moments[s, 1, y]
            for x in range(width):
                lum = luminance(r[x], g[x], b[x], luminance_weights)
                mean = mx[x] * lum + mf[x] * m1[x] + mr[x] * r1[x]
                second = mx[x] * (lum * lum) + mf[x] * m2[x] + mr[x] * r2[x]
                # The a-trous stops at the variance relative to a long causal history's
                # count: more samples than that make a cleaner colour, filtered less.
                shrink = min(_ONE, reference_counts[s] * mx[x])
                m1[x] = mean
                m2[x] = mean * mean + shrink * max(second - mean * mean, _ZERO)


@njit(inline="always", **_JIT)
def _length_of_count(table: np.ndarray, n: np.float32) -> np.float32:
    """The inverse of :func:`_count` (``table`` increasing): the history length ``h`` with
    ``n(h) = n``, linear between whole counts; 0 at n <= 0."""
    last = table.shape[0] - 1
    below = 0
    for k in range(1, last + 1):
        if table[k] <= n:
            below = k
    if below >= last:
        return F32(last)
    step = table[below + 1] - table[below]
    frac = (n - table[below]) / step if step > _ZERO else _ZERO
    return F32(below) + min(max(frac, _ZERO), _ONE)


@njit(parallel=True, **_JIT)
def consistent_lengths(
    current: np.ndarray,
    forward_moments: np.ndarray,
    forward_length: np.ndarray,
    reverse_moments: np.ndarray,
    reverse_length: np.ndarray,
    depth: np.ndarray,
    counts: np.ndarray,
    luminance_weights: tuple[np.float32, np.float32, np.float32],
    sigma: np.float32,
    forward_out: np.ndarray,
    reverse_out: np.ndarray,
) -> None:
    """The two sides' history lengths after the consistency test (module docstring).

    Per signal and surface pixel where both sides have history (``h > 0``), with first
    moments ``m_f``, ``m_r``, effective counts ``n_f``, ``n_r`` (``counts``), the per-sample
    variance ``v = max(m2_f - m_f^2, m2_r - m_r^2)`` and the current luminance ``l``:

    * the sides disagree where ``D^2 = (m_f - m_r)^2 > sigma^2 v (1/n_f + 1/n_r)``, with
      the strength ``t = 1 - sigma^2 v (1/n_f + 1/n_r) / D^2`` (0 at the threshold);
    * ``l`` decides between them: ``P_f = 1 / (1 + exp(-L))`` with the log-likelihood
      ratio ``L = ((l - m_r)^2 - (l - m_f)^2) / (2 v)``, ``c = |2 P_f - 1|``;
    * the less likely side keeps ``1 - t c`` of its effective count: its length becomes
      ``n^-1((1 - t c) n(h))`` (:func:`_length_of_count`).

    Elsewhere the lengths are copied. ``forward_out`` may be ``forward_length`` and
    ``reverse_out`` ``reverse_length`` (a pixel reads only its own length).
    """
    num_signals = current.shape[0]
    height, width = depth.shape
    two = F32(2.0)
    tiny = F32(1e-30)
    for y in prange(height):
        z = depth[y]
        nf = np.empty(width, dtype=np.float32)
        nr = np.empty(width, dtype=np.float32)
        keep = np.empty(width, dtype=np.float32)
        # the log-likelihood ratio's sign: < 0 where the forward side is the less likely
        ratio = np.empty(width, dtype=np.float32)
        for s in range(num_signals):
            hf_row = forward_length[s, y]
            hr_row = reverse_length[s, y]
            f1, f2 = forward_moments[s, 0, y], forward_moments[s, 1, y]
            r1, r2 = reverse_moments[s, 0, y], reverse_moments[s, 1, y]
            red, green, blue = current[s, 0, y], current[s, 1, y], current[s, 2, y]
            for x in range(width):  # table look-ups apart: the loop below vectorizes
                nf[x] = effective_count_at(counts, hf_row[x])
                nr[x] = effective_count_at(counts, hr_row[x])
            for x in range(width):
                both = (z[x] > _ZERO) & (nf[x] > _ZERO) & (nr[x] > _ZERO)
                var = max(max(f2[x] - f1[x] * f1[x], r2[x] - r1[x] * r1[x]), _ZERO)
                gap = f1[x] - r1[x]
                d2 = gap * gap
                allowed = sigma * sigma * var * (_ONE / max(nf[x], _ONE) + _ONE / max(nr[x], _ONE))
                strength = max(d2 - allowed, _ZERO) / max(d2, tiny)
                lum = luminance(red[x], green[x], blue[x], luminance_weights)
                to_f = (lum - f1[x]) * (lum - f1[x])
                to_r = (lum - r1[x]) * (lum - r1[x])
                llr = (to_r - to_f) / (two * max(var, tiny))
                # |2 P_f - 1| = tanh(|L| / 2), from exp(-|L|) (fast_exp takes x <= 0)
                odds = fast_exp(-abs(llr))
                confidence = (_ONE - odds) / (_ONE + odds)
                keep[x] = _ONE - strength * confidence if both else _ONE
                ratio[x] = llr
            fo = forward_out[s, y]
            ro = reverse_out[s, y]
            for x in range(width):
                hf = hf_row[x]
                hr = hr_row[x]
                if keep[x] < _ONE:  # rare: only where the sides disagree
                    if ratio[x] < _ZERO:
                        hf = min(hf, _length_of_count(counts, keep[x] * nf[x]))
                    else:
                        hr = min(hr, _length_of_count(counts, keep[x] * nr[x]))
                fo[x] = hf
                ro[x] = hr


# ----------------------------------------------------------------------------- spill format
def _scaled_half(plane: np.ndarray) -> tuple[np.ndarray, float]:
    """``plane`` as half floats scaled so its largest magnitude is HALF_TARGET, and the
    factor that restores it (``value = half * factor``)."""
    largest = float(np.max(np.abs(plane))) if plane.size else 0.0
    if not np.isfinite(largest) or largest <= 0.0:
        return np.zeros(plane.shape, dtype=np.float16), 1.0
    factor = largest / HALF_TARGET
    half = to_half(np.multiply(plane, F32(1.0 / factor), dtype=F32))
    return half, factor


def pack_history(names: tuple[str, ...], history: SideHistory,
                 half: bool = True) -> tuple[dict[str, np.ndarray], dict[str, float]]:
    """A :class:`SideHistory` as named (H, W) planes plus per-plane restore factors.

    Per signal ``<name>``: ``<name>.R/G/B`` (colour), ``<name>.m1`` (first moment),
    ``<name>.sd`` (``sqrt(max(m2 - m1^2, 0))``: the spread keeps its precision where the
    variance is small against ``m1^2``, and its range where it is large) and
    ``<name>.h`` (float32). With ``half`` the first five are float16 scaled by their own
    maximum (relative rounding <= 2^-11 for any value above 1e-8 of it); else float32.
    With running mean colours also ``albedo.<k>.R/G/B`` (as the colour) and ``albedo.<k>.h``
    (float32) for each of them.
    """
    planes: dict[str, np.ndarray] = {}
    factors: dict[str, float] = {}

    def put(channel: str, plane: np.ndarray) -> None:
        if half:
            planes[channel], factors[channel] = _scaled_half(plane)
        else:
            planes[channel] = np.array(plane, dtype=F32)
            factors[channel] = 1.0

    for s, name in enumerate(names):
        m1 = history.moments[s, 0]
        spread = np.sqrt(np.maximum(history.moments[s, 1] - m1 * m1, F32(0.0)))
        for key, plane in (("R", history.colour[s, 0]), ("G", history.colour[s, 1]),
                           ("B", history.colour[s, 2]), ("m1", m1), ("sd", spread)):
            put(f"{name}.{key}", plane)
        planes[f"{name}.h"] = np.array(history.length[s], dtype=F32)
    if history.albedo is not None and history.albedo_length is not None:
        for k in range(history.albedo.shape[0]):
            for key, plane in zip("RGB", history.albedo[k], strict=True):
                put(f"albedo.{k}.{key}", plane)
            planes[f"albedo.{k}.h"] = np.array(history.albedo_length[k], dtype=F32)
    return planes, factors


def unpack_history(names: tuple[str, ...], planes: dict[str, np.ndarray],
                   factors: dict[str, float], out: SideHistory | None = None) -> SideHistory:
    """Inverse of :func:`pack_history` (float32; ``m2 = sd^2 + m1^2``), into ``out`` when
    it has the right shapes (a run unpacks into the buffers it combines in). Consumes
    ``planes``: each packed plane is let go once restored, so the packed state and the
    unpacked one are not both held whole."""
    height, width = planes[f"{names[0]}.h"].shape
    count = len(names)
    if out is not None and out.length.shape == (count, height, width):
        colour, moments, length = out.colour, out.moments, out.length
    else:
        colour = np.empty((count, 3, height, width), dtype=F32)
        moments = np.empty((count, 2, height, width), dtype=F32)
        length = np.empty((count, height, width), dtype=F32)

    def restored(channel: str, out: np.ndarray) -> None:
        np.multiply(planes.pop(channel), F32(factors.get(channel, 1.0)), out=out, dtype=F32)

    for s, name in enumerate(names):
        for c, key in enumerate("RGB"):
            restored(f"{name}.{key}", colour[s, c])
        restored(f"{name}.m1", moments[s, 0])
        restored(f"{name}.sd", moments[s, 1])
        np.multiply(moments[s, 1], moments[s, 1], out=moments[s, 1])
        moments[s, 1] += moments[s, 0] * moments[s, 0]
        length[s] = planes.pop(f"{name}.h")
    albedo = albedo_length = None
    colours = 0
    while f"albedo.{colours}.h" in planes:
        colours += 1
    if colours:
        if (out is not None and out.albedo is not None and out.albedo_length is not None
                and out.albedo_length.shape == (colours, height, width)):
            albedo, albedo_length = out.albedo, out.albedo_length
        else:
            albedo = np.empty((colours, 3, height, width), dtype=F32)
            albedo_length = np.empty((colours, height, width), dtype=F32)
        for k in range(colours):
            for c, key in enumerate("RGB"):
                restored(f"albedo.{k}.{key}", albedo[k, c])
            albedo_length[k] = planes.pop(f"albedo.{k}.h")
    return SideHistory(colour, moments, length, albedo, albedo_length)
