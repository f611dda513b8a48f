"""Plant known bugs one at a time in a copy of the tree and check that the tests catch them.

Each mutant is a text patch (the old text must occur exactly once) plus the tests that
must fail because of it. The tree (tracked and untracked-not-ignored files, with their
modification times, and the numba kernel caches, so only the patched file's kernels are
recompiled) is copied once into a temporary folder; every mutant is applied there, its
tests are run with that copy first on ``sys.path``, and the file is restored. A baseline
run of the same tests on the unpatched copy must pass first, or "caught" means nothing.

    .venv/bin/python tests/mutants/plant.py                 # every mutant, its own tests
    .venv/bin/python tests/mutants/plant.py --list
    .venv/bin/python tests/mutants/plant.py --only taa-motion-sign --only bessel
    .venv/bin/python tests/mutants/plant.py --owner filters
    .venv/bin/python tests/mutants/plant.py --full          # the whole suite per mutant (slow)
    .venv/bin/python tests/mutants/plant.py --owner filters --tests tests/test_reference_denoiser.py

Prints a Markdown table and exits 1 when a mutant survived. Not collected by pytest (the
file name does not start with ``test_``). The list comes from issue 15's audit; add a
mutant whenever a test is written to catch a specific bug.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import shutil
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


@dataclass(frozen=True)
class Mutant:
    name: str
    owner: str  # whose tests must catch it: filters, io, farm
    bug: str
    path: str
    edits: tuple[tuple[str, str], ...]
    tests: tuple[str, ...]


FILTER_TESTS = (
    "tests/test_reference_stages.py",
    "tests/test_reference_denoiser.py",
    "tests/test_filters_stages.py",
    "tests/test_filters_denoiser.py",
    "tests/test_filters_atrous.py",
    "tests/test_filters_signals.py",
    "tests/test_filters_values.py",
    "tests/test_filters_scale.py",
    "tests/test_filters_antilag.py",
    "tests/test_filters_history_gain.py",
    "tests/test_filters_glossy.py",
    "tests/test_filters_bidirectional.py",
)
IO_TESTS = (
    "tests/test_io_presets.py",
    "tests/test_io_layers.py",
    "tests/test_io_exr.py",
    "tests/test_cli_ground_truth.py",
)
WRITE_TESTS = (
    "tests/test_io_write_safety.py",
    "tests/test_runner_output.py",
    "tests/test_io_exr.py",
    "tests/test_cli_denoise.py",
    "tests/test_farm_resume.py",
    "tests/test_farm_runner.py",
)

MUTANTS: tuple[Mutant, ...] = (
    # --- survived the audit (issue 15), must be caught now
    Mutant(
        "moments-ramp", "filters", "1/h ramp dropped for the moments only",
        "svgf_cli/filters/reproject.py",
        (("blend_moments[x] = max(moments_alpha, inv_h) if reused else _ONE",
          "blend_moments[x] = moments_alpha if reused else _ONE"),),
        FILTER_TESTS,
    ),
    Mutant(
        "no-3x3-fallback", "filters", "3x3 reprojection fallback removed",
        "svgf_cli/filters/reproject.py",
        (("            if count == 0:\n                continue\n",
          "            if True:\n                continue\n"),),
        FILTER_TESTS,
    ),
    Mutant(
        "no-boost", "filters", "4/h short-history variance boost removed",
        "svgf_cli/filters/variance.py",
        (("    boost_short_history(out_variance, history_length, threshold)\n",
          "    pass  # boost removed\n"),),
        FILTER_TESTS,
    ),
    Mutant(
        "bessel", "filters", "Bessel (reliability-weights) correction removed",
        "svgf_cli/filters/variance.py",
        (("            if shrink < _ONE:\n                population /= _ONE - shrink",
          "            if False:\n                population /= _ONE - shrink"),),
        FILTER_TESTS,
    ),
    Mutant(
        "atrous-linear-steps", "filters", "a-trous steps 1,2,3,4,5 instead of 2^i",
        "svgf_cli/filters/stages/atrous.py",
        (('            1 << iteration, p.sigma_depth, p.sigma_normal, propagate,',
          '            iteration + 1, p.sigma_depth, p.sigma_normal, propagate,'),),
        FILTER_TESTS + ("tests/test_evaluate_regression.py",),
    ),
    Mutant(
        "taa-motion-sign", "filters", "TAA motion sign flipped",
        "svgf_cli/filters/taa.py",
        (("px = F32(x) + motion[0, y, x]\n            py = F32(y) + motion[1, y, x]",
          "px = F32(x) - motion[0, y, x]\n            py = F32(y) - motion[1, y, x]"),),
        FILTER_TESTS,
    ),
    Mutant(
        "taa-everywhere", "filters", "TAA blends inside surfaces too (no outline test)",
        "svgf_cli/filters/taa.py",
        (("            if depth[y, x] <= _ZERO or not _near_jump(jumps, y, x):",
          "            if depth[y, x] <= _ZERO:"),),
        FILTER_TESTS,
    ),
    Mutant(
        "taa-unclipped", "filters", "TAA history not clipped to the current 3x3",
        "svgf_cli/filters/taa.py",
        (("    return min(max(t, low), high)\n", "    return t\n"),),
        FILTER_TESTS,
    ),
    Mutant(
        "pixel-filter-everywhere", "filters",
        "pixel filter auto applied to frames that are not centre-sampled",
        "svgf_cli/filters/pixel_filter.py",
        (("    return CENTRE_SAMPLE_WEIGHT if centre_sampled else 0.0\n",
          "    return CENTRE_SAMPLE_WEIGHT\n"),),
        FILTER_TESTS,
    ),
    Mutant(
        "pixel-filter-blurs-lights", "filters", "pixel filter blurs the emission too",
        "svgf_cli/filters/pixel_filter.py",
        (("                target[x] = centre * here[c, x] + weight * (up[c, x] + down[c, x]) "
          "+ light[x]",
          "                target[x] = centre * here[c, x] + weight * (up[c, x] + down[c, x]) "
          "+ light[x] * centre"),),
        FILTER_TESTS,
    ),
    Mutant(
        "centre-sampled-any-count", "io", "any Cycles sample count read as centre-sampled",
        "svgf_cli/io/exr.py",
        (("                if int(str(value).strip()) == 1:",
          "                if int(str(value).strip()) >= 1:"),),
        IO_TESTS,
    ),
    Mutant(
        "arnold-backward", "io", "Arnold preset treated as backward motion",
        "svgf_cli/io/layers.py",
        (('    "arnold": "forward-pixels",', '    "arnold": "backward-pixels",'),),
        IO_TESTS,
    ),
    # --- caught by the audit, must stay caught
    Mutant(
        "reproject-motion-sign", "filters", "motion sign flipped in reprojection",
        "svgf_cli/filters/reproject.py",
        (("px = F32(x + origin_x) + motion[0, uy, ux]\n"
          "        py = F32(y + origin_y) + motion[1, uy, ux]",
          "px = F32(x + origin_x) - motion[0, uy, ux]\n"
          "        py = F32(y + origin_y) - motion[1, uy, ux]"),),
        FILTER_TESTS + ("tests/test_cli_ground_truth.py",),
    ),
    Mutant(
        "cycles-y", "io", "Cycles Y not flipped",
        "svgf_cli/io/layers.py",
        (("        np.negative(xy[1], out=out[1])", "        out[1] = xy[1]"),),
        IO_TESTS,
    ),
    Mutant(
        "no-ramp", "filters", "1/h ramp dropped (colour and moments)",
        "svgf_cli/filters/reproject.py",
        (("blend[x] = max(alpha, inv_h) if reused else _ONE",
          "blend[x] = alpha if reused else _ONE"),
         ("blend_moments[x] = max(moments_alpha, inv_h) if reused else _ONE",
          "blend_moments[x] = moments_alpha if reused else _ONE")),
        FILTER_TESTS,
    ),
    Mutant(
        "variance-w", "filters", "w instead of w^2 in variance propagation",
        "svgf_cli/filters/atrous.py",
        # The pair's second signal and the triple's second and third (the first signal's line
        # is the same text in both row functions).
        (("fma(w1 * w1, variance[second, uq, qx], acc[9])",
          "fma(w1, variance[second, uq, qx], acc[9])"),
         ("fma(w1 * w1, variance[1, uq, qx], acc[9])", "fma(w1, variance[1, uq, qx], acc[9])"),
         ("fma(w2 * w2, variance[2, uq, qx], acc[14])", "fma(w2, variance[2, uq, qx], acc[14])")),
        FILTER_TESTS,
    ),
    Mutant(
        "no-depth-test", "filters", "reprojection depth test removed",
        "svgf_cli/filters/reproject.py",
        (("    if abs(z_prev - z) > max_depth_diff:\n        return False\n", ""),),
        FILTER_TESTS,
    ),
    Mutant(
        "id-truncated", "io", "mesh id truncated instead of rounded",
        "svgf_cli/io/exr.py",
        (("rounded = np.rint(raw_id[finite].astype(np.float64))",
          "rounded = np.trunc(raw_id[finite].astype(np.float64))"),),
        IO_TESTS,
    ),
    Mutant(
        "empty-depth-kept", "io", "a depth with no surface kept (Cycles' Depth with a sample "
        "offset: every frame written unfiltered)",
        "svgf_cli/io/exr.py",
        (("    if np.any(depth[0] > 0):\n        return depth\n",
          "    if True:\n        return depth\n"),),
        IO_TESTS,
    ),
    Mutant(
        "skip-existing-no-replay", "farm", "--skip-existing (and chunks) not replaying history",
        "svgf_cli/farm/job.py",
        (("frames = [(f, p) for f, p in usable if chunk.read_start <= f <= last_read]",
          "frames = [(f, p) for f, p in usable if f in write]"),),
        ("tests/test_farm_resume.py", "tests/test_farm_chunks.py"),
    ),
    # --- the generalised filter (signals branch): N signals, modes, values, colour space
    Mutant(
        "reproject-mode-blind", "filters", "mode test removed from reprojection",
        "svgf_cli/filters/reproject.py",
        (("relevant = np.uint16(1 << s) | NO_HISTORY", "relevant = NO_HISTORY"),),
        FILTER_TESTS,
    ),
    Mutant(
        "history-length-of-signal-0", "filters",
        "per-signal history length replaced by signal 0's",
        "svgf_cli/filters/stages/reproject.py",
        (('            ctx.temporal = TemporalState(\n',
          '            history_length[1:] = history_length[0]\n'
          '            ctx.temporal = TemporalState(\n'),),
        FILTER_TESTS,
    ),
    Mutant(
        "rec709-weights", "filters", "luminance weights ignored (Rec.709 constants used)",
        "svgf_cli/filters/engine.py",
        (('float32_weights(frame.luminance_weights),',
          'float32_weights((0.2126, 0.7152, 0.0722)),'),),
        FILTER_TESTS,
    ),
    Mutant(
        "no-history-guard", "filters", "history guard removed",
        "svgf_cli/filters/stages/store_history.py",
        (('        counts["history_resets"] += values.reset_nonfinite_history(\n'
          '            history["history_illumination"], history["history_moments"],\n'
          '            history["history_length"], history["history_mode"],\n'
          '        )\n',
          '        counts["history_resets"] += 0\n'),),
        FILTER_TESTS,
    ),
    Mutant(
        "antilag-no-history-share", "filters",
        "anti-lag ignores the history's own noise (short histories look stale)",
        "svgf_cli/filters/antilag.py",
        (("stale = diff2 > k0_2 * var * inv_n * (_ONE + share) + tol2 * level * level",
          "stale = diff2 > k0_2 * var * inv_n + tol2 * level * level"),),
        FILTER_TESTS,
    ),
    Mutant(
        "antilag-no-ramp", "filters",
        "anti-lag gives its full weight from the ramp's start (a step at antilag_sigma_start)",
        "svgf_cli/filters/antilag.py",
        (("ramp = min((z - sigma_start) * ramp_slope, _ONE)", "ramp = _ONE"),),
        FILTER_TESTS,
    ),
    Mutant(
        "history-gain-no-check", "filters",
        "the history gain rescales by the wide window's factor without the narrower windows'"
        " check (a light reaching part of the window rescales the rest)",
        "svgf_cli/filters/history_gain.py",
        (("GAIN_CHECK_SCALES = (2, 1)", "GAIN_CHECK_SCALES = ()"),),
        FILTER_TESTS,
    ),
    Mutant(
        "history-gain-unshrunk", "filters",
        "the history gain applies the wide window's ratio unshrunk by its noise",
        "svgf_cli/filters/history_gain.py",
        (("g = _ONE + bias2 / (bias2 + error2 + F32(1e-30)) * (ratio - _ONE)", "g = ratio"),),
        FILTER_TESTS,
    ),
    Mutant(
        "antilag-no-dilation", "filters", "anti-lag weight not dilated over neighbouring cells",
        "svgf_cli/filters/antilag.py",
        (("        for cx in range(1, cells_x):\n"
          "            dilated[cx] = max(dilated[cx], best[cx - 1])\n", ""),),
        FILTER_TESTS,
    ),
    Mutant(
        "antilag-temporal-variance-only", "filters",
        "anti-lag noise from the history's temporal variance alone (no sample variance)",
        "svgf_cli/filters/antilag.py",
        (("var = max(spread * n / max(n - _ONE, _ONE), sums[4, cx] * inv_n)",
          "var = sums[4, cx] * inv_n"),),
        FILTER_TESTS,
    ),
    Mutant(
        "antilag-gradients-ungated", "filters",
        "gradient samples used without their significance test",
        "svgf_cli/filters/antilag.py",
        (("gradient_bias = change * mean_h if significant else _ZERO",
          "gradient_bias = change * mean_h"),),
        FILTER_TESTS,
    ),
    Mutant(
        "glossy-no-clamp", "filters", "glossy signals' history not clamped",
        "svgf_cli/filters/stages/history_clamp.py",
        (('    return [glossy_k if g else params.history_clamp for g in glossy]',
          '    return [params.history_clamp for g in glossy]'),),
        FILTER_TESTS,
    ),
    Mutant(
        "clamp-keeps-moments", "filters", "history clamp leaves the moments of a clamped outlier",
        "svgf_cli/filters/clamp.py",
        (("                if moved[x]:\n                    _follow_luminance(",
          "                if False:\n                    _follow_luminance("),),
        FILTER_TESTS,
    ),
    Mutant(
        "guide-floor-ignored", "filters",
        "signals demodulated by the G-buffer albedo get no floor",
        "svgf_cli/filters/context.py",
        (('params.guide_albedo_floor if guide else 0.0',
          '0.0'),),
        FILTER_TESTS,
    ),
    Mutant(
        "guide-flag-dropped", "io", "a combined signal is not marked as demodulated by the "
        "albedo AOV",
        "svgf_cli/io/signals.py",
        (("                              guide_albedo=recipe.guide_albedo, mixed=recipe.mixed))",
          "                              mixed=recipe.mixed))"),),
        ("tests/test_io_signals.py", *IO_TESTS),
    ),
    Mutant(
        "despike-ignores-modes", "filters", "despike compares neighbours of the other mode",
        "svgf_cli/filters/despike.py",
        (("                candidate = lum_row[q] if (differing & bit) == 0 else _NONE",
          "                candidate = lum_row[q]"),),
        FILTER_TESTS,
    ),
    Mutant(
        "despike-changes-history", "filters", "despike runs on the colour history too",
        "svgf_cli/filters/stages/despike.py",
        (('        if filtered.name == filtered.history_name:\n'
          '            illumination = illumination.copy()\n',
          ''),),
        FILTER_TESTS,
    ),
    Mutant(
        "despike-brightest-only", "filters",
        "despike bounds by the brightest neighbour, so a pair of spikes shelters itself",
        "svgf_cli/filters/despike.py",
        (("                reference = second[x] if second[x] > _NONE else brightest[x]",
          "                reference = brightest[x]"),),
        FILTER_TESTS,
    ),
    Mutant(
        "mixed-sigma-ignored", "filters",
        "a signal mixing direct and indirect light stops at the diffuse sigma_l",
        "svgf_cli/filters/stages/atrous.py",
        (('    if signal.mixed:\n',
          '    if False:\n'),),
        FILTER_TESTS,
    ),
    Mutant(
        "lobe-pair-guide-unmarked", "io",
        "direct + indirect summed from lobes over the albedo AOV is not marked as guided",
        "svgf_cli/io/signals.py",
        (("                         guide_albedo=albedo == (\"albedo\",))",
          "                         guide_albedo=False)"),),
        ("tests/test_io_signals.py", *IO_TESTS),
    ),
    Mutant(
        "combined-not-mixed", "io",
        "the combined colour is not marked as mixing direct and indirect light",
        "svgf_cli/io/signals.py",
        (("                         guide_albedo=True, mixed=True),), False",
          "                         guide_albedo=True),), False"),),
        ("tests/test_io_signals.py", *IO_TESTS),
    ),
    Mutant(
        "fireflies-drop-excess", "filters",
        "firefly spreading clamps the sample and drops its excess (energy lost)",
        "svgf_cli/filters/fireflies.py",
        (("                        illumination[c, yy, xx] += excess[i, c] * share",
          "                        illumination[c, yy, xx] += _ZERO * share"),),
        FILTER_TESTS,
    ),
    Mutant(
        "fireflies-spread-glossy", "filters",
        "a glossy signal's firefly is spread over the 9x9 (a small highlight smeared)",
        "svgf_cli/filters/stages/spread_fireflies.py",
        (('            tuple(glossy_radius if g else RADIUS for g in glossy),',
          '            tuple(RADIUS for g in glossy),'),),
        FILTER_TESTS,
    ),
    Mutant(
        "fireflies-glossy-uncapped", "filters",
        "a glossy firefly's share is not capped at its bound (a hit becomes a bright block)",
        "svgf_cli/filters/fireflies.py",
        (("        if capped:  # each receiver gains at most the firefly's own bound",
          "        if False:  # each receiver gains at most the firefly's own bound"),),
        FILTER_TESTS,
    ),
    Mutant(
        "fireflies-glossy-left-alone", "filters",
        "glossy_spread_fireflies is ignored: a glossy signal's fireflies are never spread",
        "svgf_cli/filters/stages/spread_fireflies.py",
        (("        glossy_radius = GLOSSY_RADIUS if ctx.params.glossy_spread_fireflies else 0",
          "        glossy_radius = 0"),),
        FILTER_TESTS,
    ),
    Mutant(
        "glossy-heavy-tail-ignored", "filters",
        "glossy_heavy_tail is ignored: a heavy-tailed glossy history keeps the 3x3 clamp",
        "svgf_cli/filters/stages/history_clamp.py",
        (("    if threshold <= 0.0 or radius <= 1 or not own_k or not any(glossy) or temporal"
          " is None:",
          "    if True:"),),
        FILTER_TESTS,
    ),
    Mutant(
        "glossy-heavy-tail-rough-too", "filters",
        "rough objects' heavy-tailed glossy histories take the wide clamp window too",
        "svgf_cli/filters/clamp.py",
        (("                if k >= 0 and k < entries and rough_table[k] > 0:",
          "                if k >= 0 and k < entries and rough_table[k] > 1:"),),
        FILTER_TESTS,
    ),
    Mutant(
        "fireflies-cross-depth-edges", "filters",
        "a firefly's excess is shared with pixels of another surface",
        "svgf_cli/filters/fireflies.py",
        (("    return (zq > _ZERO and (mode_q & bit) == 0 and abs(zq - z) <= DEPTH_TOLERANCE * z\n",
          "    return (zq > _ZERO and (mode_q & bit) == 0\n"),),
        FILTER_TESTS,
    ),
    Mutant(
        "fireflies-guide-any-colour", "filters",
        "a firefly under the G-buffer albedo shares its light with brighter colours too",
        "svgf_cli/filters/fireflies.py",
        (("        tolerance = ALBEDO_TOLERANCE if guide[s] else ANY_COLOUR",
          "        tolerance = ANY_COLOUR"),),
        FILTER_TESTS,
    ),
    Mutant(
        "fireflies-no-neighbour-test", "filters",
        "a sample above its history's bound is a firefly whatever its neighbours show",
        "svgf_cli/filters/fireflies.py",
        (("            bound = max(lum - margin, ratio * max(reference, _ZERO))",
          "            bound = lum - margin"),),
        FILTER_TESTS,
    ),
    Mutant(
        "clamp-scales-raised-moments", "filters",
        "a history raised from near black scales its moments by (l'/l)^2 (overflow)",
        "svgf_cli/filters/clamp.py",
        (("    if before > _ZERO and after <= MAX_RAISE * before:",
          "    if before > _ZERO:"),),
        FILTER_TESTS,
    ),
    Mutant(
        "clamp-second-moment-uncapped", "filters",
        "the history clamp's scaled second moment overflows to inf",
        "svgf_cli/filters/clamp.py",
        (("        m2[x] = min(m2[x] * (ratio * ratio), MAX_SECOND_MOMENT)",
          "        m2[x] = m2[x] * (ratio * ratio)"),),
        FILTER_TESTS,
    ),
    Mutant(
        "auto-iterations-fixed", "filters", "auto a-trous iterations always run the paper's 5",
        "svgf_cli/filters/params.py",
        (("    count = next(count for smallest, count in _ITERATION_SIDES if side >= smallest)",
          "    count = 5"),),
        FILTER_TESTS,
    ),
    Mutant(
        "auto-iterations-ignore-samples", "filters",
        "frames of several samples per pixel get the one-sample a-trous count",
        "svgf_cli/filters/params.py",
        (("    return max(1, count - factors_of_four(params, samples_per_pixel))",
          "    return count"),),
        FILTER_TESTS,
    ),
    Mutant(
        "antilag-window-ignores-samples", "filters",
        "frames of several samples per pixel get the one-sample anti-lag window",
        "svgf_cli/filters/params.py",
        (("    for _ in range(factors_of_four(params, samples_per_pixel)):",
          "    for _ in range(0):"),),
        FILTER_TESTS,
    ),
    Mutant(
        "colour-blend-ignores-samples", "filters",
        "the colours' running means of several-sample frames blend at the light's rate",
        "svgf_cli/filters/engine.py",
        (("            albedo_blend = colour_blend_for(self.params, samples_per_pixel)",
          "            albedo_blend = params.alpha"),),
        FILTER_TESTS,
    ),
    Mutant(
        "despike-lone-skipped", "filters",
        "a pixel filtered alone in its mode is never compared with its output neighbours",
        "svgf_cli/filters/stages/despike_lone.py",
        (('        return params.despike > 0.0\n',
          '        return False\n'),),
        FILTER_TESTS,
    ),
    Mutant(
        "despike-lone-everywhere", "filters", "the output guard bounds every pixel, lone or not",
        "svgf_cli/filters/despike.py",
        (("            lone = (agreeing[x] & all_bits) != all_bits",
          "            lone = True"),),
        FILTER_TESTS,
    ),
    Mutant(
        "reverse-pass-drops-glossy", "filters", "the reverse pass forgets which signals are glossy",
        "svgf_cli/filters/two_pass.py",
        (("signals=[dataclasses.replace(s, gradient=None) for s in frame.signals],",
          "signals=[dataclasses.replace(s, gradient=None, glossy=False) "
          "for s in frame.signals],"),),
        FILTER_TESTS,
    ),
    Mutant(
        "consistency-drops-agreeing-side", "filters",
        "the consistency test shortens the side the current frame agrees with",
        "svgf_cli/filters/bidirectional.py",
        (("                    if ratio[x] < _ZERO:",
          "                    if ratio[x] > _ZERO:"),),
        FILTER_TESTS,
    ),
    Mutant(
        "consistency-skipped", "filters",
        "a bidirectional run combines without the consistency test",
        "svgf_cli/filters/stages/combine.py",
        (('            reverse_length, temporal.depth, setup.colour_counts,',
          '            temporal.history_length, temporal.depth, setup.colour_counts,'),),
        FILTER_TESTS,
    ),
    Mutant(
        "bidirectional-antilag-causal-sigma", "filters",
        "the passes of a bidirectional run test their history at the causal significance",
        "svgf_cli/filters/stages/antilag.py",
        (('(PASS_ANTILAG_SIGMA_SCALE if bidirectional else 1.0)',
          '(1.0 if bidirectional else 1.0)'),),
        FILTER_TESTS,
    ),
    Mutant(
        "bidirectional-glossy-reference-count", "filters",
        "a bidirectional run scales a glossy signal's variance as any other signal's",
        "svgf_cli/filters/stages/combine.py",
        (('[GLOSSY_REFERENCE_COUNT if signal.glossy else setup.moment_counts[-1]',
          '[setup.moment_counts[-1] if signal.glossy else setup.moment_counts[-1]'),),
        FILTER_TESTS,
    ),
    Mutant(
        "bidirectional-static-history-unfiltered", "filters",
        "the passes of a bidirectional run keep no filtered colour where pixels stand still",
        "svgf_cli/filters/stages/pass_history.py",
        (('F32(STATIC_MOTION), F32(STATIC_FILTERED_SHARE), F32(0.0))',
          'F32(STATIC_MOTION), F32(0.0), F32(0.0))'),),
        FILTER_TESTS,
    ),
    Mutant(
        "glossy-sigma-ignored", "filters", "glossy signals filtered with the common sigma_l",
        "svgf_cli/filters/stages/atrous.py",
        (('        return params.glossy_sigma_luminance or params.sigma_luminance',
          '        return params.sigma_luminance'),),
        FILTER_TESTS,
    ),
    Mutant(
        "emitter-mode-ignored", "filters",
        "glossy signals demodulated where the G-buffer albedo marks a reflected light",
        "svgf_cli/filters/stages/reflected_lights.py",
        (('        return params.glossy_emitter_radiance\n',
          '        return False\n'),),
        FILTER_TESTS,
    ),
    Mutant(
        "emitter-lone-hits", "filters",
        "a reflected-light pair (one lit neighbour) filtered as radiance too",
        "svgf_cli/filters/modulate.py",
        (("LIT_NEIGHBOURS_ROUGH = 2", "LIT_NEIGHBOURS_ROUGH = 1"),),
        FILTER_TESTS,
    ),
    Mutant(
        "variance-mode-blind", "filters", "mode test removed from the spatial variance",
        "svgf_cli/filters/variance.py",
        (("w = w if (mode_p[i] ^ mode_q[i]) & bit == 0 else _ZERO", "w = w"),),
        FILTER_TESTS,
    ),
    Mutant(
        "atrous-mode-blind", "filters", "a-trous ignores the mode (guide sign)",
        "svgf_cli/filters/atrous.py",
        # In the pair's tap and in the triple's (whose third line makes the text unique).
        (("    w0 = w0 if (guide0 < _ZERO) == (lum0 < _ZERO) else _ZERO\n"
          "    w1 = w1 if (guide1 < _ZERO) == (lum1 < _ZERO) else _ZERO\n    return",
          "    return"),
         ("    w0 = w0 if (guide0 < _ZERO) == (lum0 < _ZERO) else _ZERO\n"
          "    w1 = w1 if (guide1 < _ZERO) == (lum1 < _ZERO) else _ZERO\n"
          "    w2 = w2 if (guide2 < _ZERO) == (lum2 < _ZERO) else _ZERO\n", "")),
        FILTER_TESTS,
    ),
    Mutant(
        "implausible-demodulated", "filters", "colours above 1.05 demodulated",
        "svgf_cli/filters/modulate.py",
        (("if not (brightest >= black and brightest <= max_reflectance):",
          "if not brightest >= black:"),),
        FILTER_TESTS,
    ),
    Mutant(
        "absolute-albedo-floor", "filters", "demodulation floor not relative to max(a)",
        "svgf_cli/filters/modulate.py",
        (("floor = max(black, relative_floor * brightest)", "floor = black"),),
        FILTER_TESTS,
    ),
    Mutant(
        "extreme-radiance-kept", "filters", "radiance beyond 1e15 kept (only NaN/Inf cleaned)",
        "svgf_cli/filters/modulate.py",
        (("return v if is_usable(v) else _ZERO", "return _ZERO if is_nonfinite(v) else v"),),
        FILTER_TESTS,
    ),
    Mutant(
        "emission-per-signal", "filters", "emission added once per signal",
        "svgf_cli/filters/stages/remodulate.py",
        (('add_emission = has_emission and index == 0',
          'add_emission = has_emission'),),
        FILTER_TESTS,
    ),
    Mutant(
        "absolute-deviation-floor", "filters", "a-trous deviation floor absolute (1e-5)",
        "svgf_cli/filters/atrous.py",
        (("floor = RELATIVE_DEVIATION_FLOOR * lum", "floor = RELATIVE_DEVIATION_FLOOR"),),
        FILTER_TESTS,
    ),
    # --- write safety: the io engineer's tests (issue 15 item 3); listed to run after merge
    Mutant(
        "temp-copied", "io", "output temp file copied instead of renamed",
        "svgf_cli/io/atomic.py",
        (("        os.replace(tmp, final)\n",
          "        __import__('shutil').copyfile(tmp, final)\n        tmp.unlink()\n"),),
        WRITE_TESTS,
    ),
    Mutant(
        "temp-not-hidden", "io", "temp name not hidden",
        "svgf_cli/io/atomic.py",
        (('f".{path.name}.{_host()}_{_pid_namespace()}.{os.getpid()}.{token}.tmp{ext}"',
          'f"{path.name}.{_host()}_{_pid_namespace()}.{os.getpid()}.{token}.tmp{ext}"'),),
        WRITE_TESTS,
    ),
    Mutant(
        "history-no-temp", "io", "history .npz written without a temp file",
        "svgf_cli/run/history.py",
        (('        with atomic_target(path) as tmp, open(tmp, "wb") as handle:',
          '        with open(path, "wb") as handle:'),),
        WRITE_TESTS,
    ),
    Mutant(
        "alpha-always-1", "io", "output alpha dropped (stand-in readers' layout)",
        "svgf_cli/io/output.py",
        (("    if alpha is not None:\n        from svgf_cli.io.source import SourceChannel",
          "    if False:\n        from svgf_cli.io.source import SourceChannel"),),
        WRITE_TESTS,
    ),
    Mutant(
        "albedo-history-unclamped", "filters",
        "temporal albedo: the resampled mean is not clamped to the current 3x3 range",
        "svgf_cli/filters/albedo_history.py",
        (("            m_r = min(max(h_r, lo[0, x]), hi[0, x])\n",
          "            m_r = h_r\n"),),
        ("tests/test_filters_albedo_history.py",),
    ),
    Mutant(
        "albedo-history-no-mode-guard", "filters",
        "temporal albedo: a running mean that is not a reflectance is kept",
        "svgf_cli/filters/albedo_history.py",
        (("            if not mean:\n                continue  # another mode",
          "            if False:\n                continue  # another mode"),),
        ("tests/test_filters_albedo_history.py",),
    ),
    Mutant(
        "albedo-history-not-composed", "filters",
        "temporal albedo: the running mean is computed but the output is remodulated by"
        " this frame's colour",
        "svgf_cli/filters/stages/temporal_albedo.py",
        (('        ctx.frame = dataclasses.replace(frame, signals=signals)\n'
          '        return True',
          '        ctx.frame = frame\n'
          '        return True'),),
        ("tests/test_filters_albedo_history.py",),
    ),
    Mutant(
        "albedo-history-glossy-averaged", "filters",
        "temporal albedo: a glossy signal is remodulated by its colour's running mean too",
        "svgf_cli/filters/stages/temporal_albedo.py",
        (('        if signal.glossy:\n'
          '            slots.append(-1)',
          '        if False:\n'
          '            slots.append(-1)'),),
        ("tests/test_filters_albedo_history.py", "tests/test_reference_denoiser.py"),
    ),
    Mutant(
        "albedo-history-mixes-modes", "filters",
        "temporal albedo: history taps whose mean is not a reflectance are resampled too",
        "svgf_cli/filters/albedo_history.py",
        (("    _reflectances(history, prev_depth, black, max_reflectance, relative_floor, kept)",
          "    np.copyto(kept, prev_depth > 0)"),),
        ("tests/test_filters_albedo_history.py",),
    ),
    Mutant(
        "albedo-history-no-first-estimate", "filters",
        "temporal albedo: without history the colour is this frame's sample, not the 3x3"
        " Gaussian mean",
        "svgf_cli/filters/albedo_history.py",
        (("                m_r, m_g, m_b = _gaussian_mean(albedo, usable, mesh_id, x, y)\n",
          "                m_r, m_g, m_b = a_r, a_g, a_b\n"),),
        ("tests/test_filters_albedo_history.py",),
    ),
    Mutant(
        "albedo-bidirectional-reverse-only", "filters",
        "temporal albedo: a bidirectional output is remodulated by the reverse pass's mean"
        " alone",
        "svgf_cli/filters/stages/combine_albedo.py",
        (('        if forward is None or ctx.forward is None or ctx.forward.albedo is None:\n',
          '        if True:\n'),),
        ("tests/test_filters_albedo_history.py",),
    ),
    Mutant(
        "albedo-not-spilled", "filters",
        "temporal albedo: the forward pass's colour means are left out of the spill",
        "svgf_cli/filters/bidirectional.py",
        (("    if history.albedo is not None and history.albedo_length is not None:\n",
          "    if False:\n"),),
        ("tests/test_filters_albedo_history.py", "tests/test_bidir_runs.py"),
    ),
    Mutant(
        "combination-buffers-kept", "filters",
        "memory: the reverse pass keeps its combination buffers between output frames",
        "svgf_cli/filters/stages/release.py",
        (('            ctx.work.planes.pop(name, None)\n'
          '        ctx.resident.forward_albedo = None\n',
          '            pass\n'),),
        ("tests/test_filters_bidirectional.py",),
    ),
    Mutant(
        "read-beside-write", "io",
        "memory: the reverse pass reads a frame while two others are in memory",
        "svgf_cli/run/bidirectional.py",
        (("stats, after=writes.in_flight) as reads,", "stats) as reads,"),),
        ("tests/test_bidir_memory.py",),
    ),
    Mutant(
        "moving-feedback-ignored", "filters",
        "causal feedback: the filtered output kept as history where pixels move too",
        "svgf_cli/filters/stages/atrous.py",
        (('    keep_unfiltered = feedback >= 0 and p.moving_feedback_share < 1.0\n',
          '    keep_unfiltered = False\n'),),
        ("tests/test_filters_denoiser.py", "tests/test_reference_denoiser.py"),
    ),
    Mutant(
        "moving-feedback-still-blended", "filters",
        "causal feedback: still pixels keep the moving share too (the blend ignores motion)",
        "svgf_cli/filters/feedback.py",
        (("            w[x] = still_share if still else moving_share\n",
          "            w[x] = moving_share\n"),),
        ("tests/test_filters_feedback.py", "tests/test_filters_denoiser.py"),
    ),
    Mutant(
        "catmull-rom-unclamped", "filters",
        "Catmull-Rom history fetch: the clamp to the bilinear taps' range removed (ringing,"
        " negative colour)",
        "svgf_cli/filters/resample.py",
        (("    return min(max(total, lo), hi)\n", "    return total\n"),),
        ("tests/test_reference_stages.py", "tests/test_filters_resample.py"),
    ),
    Mutant(
        "catmull-rom-outer-taps-untested", "filters",
        "Catmull-Rom history fetch: the taps outside the bilinear 2x2 are not tested",
        "svgf_cli/filters/reproject.py",
        (("                return False\n            if prev_mode[U(ty), U(tx)] != m:\n",
          "                pass\n            if prev_mode[U(ty), U(tx)] != m:\n"),),
        ("tests/test_reference_stages.py", "tests/test_filters_resample.py"),
    ),
    Mutant(
        "albedo-catmull-rom-mesh-blind", "filters",
        "temporal albedo's Catmull-Rom fetch: support taps of another mesh id accepted",
        "svgf_cli/filters/albedo_history.py",
        (("            if not kept[qy, qx] or prev_mesh_id[qy, qx] != mesh:\n"
          "                return False\n",
          "            if not kept[qy, qx]:\n                return False\n"),),
        ("tests/test_filters_albedo_history.py",),
    ),
    Mutant(
        "medium-not-filled", "filters",
        "medium pixels (a sample scattered in fog) keep their no-surface G-buffer",
        "svgf_cli/filters/medium.py",
        (("            out[y, x] = best\n",
          "            out[y, x] = NO_FILL if best >= 0 else best\n"),),
        ("tests/test_filters_medium.py",),
    ),
    Mutant(
        "medium-emission-raw", "filters",
        "the emission of medium pixels (the sky seen through smoke) added back raw",
        "svgf_cli/filters/stages/fill_medium.py",
        (("        if emission is not None and medium is not None:\n",
          "        if False:\n"),),
        ("tests/test_filters_medium.py",),
    ),
    Mutant(
        "warm-start-ignored", "farm", "the look-ahead warm start never runs",
        "svgf_cli/run/chunk.py",
        (("head = warm_head(tasks, warm_start)", "head = warm_head(tasks, 0)"),),
        ("tests/test_run_warm_start.py",),
    ),
    Mutant(
        "warm-start-short-look-ahead", "farm",
        "a cold chunk does not read the warm start's look-ahead frames",
        "svgf_cli/farm/plan.py",
        (("start + 2 * warm_start - 1", "start + warm_start - 1"),),
        ("tests/test_run_warm_start.py",),
    ),
    Mutant(
        "halfres-upsample-ignores-surface", "filters",
        "the groups' upsampling blends blocks of another object into a pixel",
        "svgf_cli/filters/halfres.py",
        (("w *= F32(FOREIGN_WEIGHT)", "w *= F32(1.0)"),),
        ("tests/test_filters_halfres.py",),
    ),
    Mutant(
        "halfres-farthest-surface", "filters",
        "a block takes its farthest pixel's G-buffer, not its nearest",
        "svgf_cli/filters/halfres.py",
        (("if depth[y, x] < best:", "if depth[y, x] > best:"),),
        ("tests/test_filters_halfres.py",),
    ),
    Mutant(
        "antilag-debug-stale", "filters",
        "a cold frame's anti-lag layer shows the response kept from before a reset",
        "svgf_cli/filters/stages/remodulate.py",
        (("if \"antilag\" in ctx.counts else", "if True else"),),
        ("tests/test_filters_denoiser.py",),
    ),
    Mutant(
        "lone-light-unbounded", "filters",
        "near a lone light the filtered groups are no longer held to the colour",
        "svgf_cli/filters/composable.py",
        (("    if lone is not None:\n        bound_by_total(",
          "    if False:\n        bound_by_total("),),
        ("tests/test_light_layers.py",),
    ),
    Mutant(
        "lone-light-albedo-kept", "filters",
        "the groups' filter demodulates a lone light by its own (emission) albedo",
        "svgf_cli/filters/composable.py",
        (("    albedo = (frame.albedo if lone is None\n", "    albedo = (frame.albedo if True\n"),),
        ("tests/test_light_layers.py",),
    ),
    Mutant(
        "lone-light-in-smoke", "filters",
        "the medium's own noisy albedo counts as lone lights (bounds the groups all over smoke)",
        "svgf_cli/filters/composable.py",
        (("    kept = ~(medium[ys, xs] & ", "    kept = (medium[ys, xs] | ~"),),
        ("tests/test_light_layers.py",),
    ),
    Mutant(
        "lone-light-rest-shared", "filters",
        "what the colour kept of a lone light's sample is shared by all the groups",
        "svgf_cli/filters/composable.py",
        (("        give_to_their_groups(filtered, colour, radiance, lone)\n", ""),),
        ("tests/test_light_layers.py",),
    ),
    Mutant(
        "lone-light-owner-last", "filters",
        "a lone light's rest goes to the group with the least light there",
        "svgf_cli/filters/lone_lights.py",
        (("    owner = np.argmax([inp[:, ys, xs]", "    owner = np.argmin([inp[:, ys, xs]"),),
        ("tests/test_filters_lone_lights.py",),
    ),
    Mutant(
        "lone-light-tent-clipped", "filters",
        "the lone lights' tents cut at the image's border before their second box",
        "svgf_cli/filters/lone_lights.py",
        (("    top, left = int(ys.min()) - reach, int(xs.min()) - reach\n",
          "    top, left = max(int(ys.min()) - reach, 0), max(int(xs.min()) - reach, 0)\n"),),
        ("tests/test_filters_lone_lights.py",),
    ),
)


def _tree_files() -> list[str]:
    listed = subprocess.run(
        ["git", "ls-files", "-co", "--exclude-standard", "-z"], cwd=ROOT, check=True,
        capture_output=True,
    ).stdout.decode().split("\0")
    caches = [str(p.relative_to(ROOT)) for p in ROOT.glob("svgf_*/**/__pycache__/*.nb[ic]")]
    return [name for name in listed if name and (ROOT / name).is_file()] + caches


def copy_tree(destination: Path) -> None:
    """The tree with modification times kept, so numba's caches stay valid."""
    for name in _tree_files():
        target = destination / name
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(ROOT / name, target)


def _environment(copy: Path) -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(copy), env.get("PYTHONPATH", "")]).rstrip(os.pathsep)
    env["PYTHONDONTWRITEBYTECODE"] = "1"
    return env


def check_import_location(copy: Path) -> None:
    located = subprocess.run(
        [sys.executable, "-c", "import svgf_cli; print(svgf_cli.__file__)"], cwd=copy,
        env=_environment(copy), check=True, capture_output=True, text=True,
    ).stdout.strip()
    if not Path(located).resolve().is_relative_to(copy.resolve()):
        raise SystemExit(f"svgf_cli imports from {located}, not from the copy {copy}")


def run_tests(copy: Path, tests: tuple[str, ...], full: bool) -> tuple[int, str, float]:
    """pytest in the copy: (exit code, first failing test or last line, seconds)."""
    args = [sys.executable, "-m", "pytest", "-x", "-rfE", "-p", "no:cacheprovider"]
    if not full:
        args += list(tests)
    start = time.perf_counter()
    done = subprocess.run(args, cwd=copy, env=_environment(copy), capture_output=True,
                          text=True)
    seconds = time.perf_counter() - start
    lines = done.stdout.splitlines()
    failed = [line for line in lines if line.startswith(("FAILED", "ERROR"))]
    summary = failed[0] if failed else (lines[-1] if lines else done.stderr.strip()[-200:])
    return done.returncode, summary, seconds


def _patch(file: Path, mutant: Mutant) -> str:
    original = file.read_text()
    text = original
    for old, new in mutant.edits:
        count = text.count(old)
        if count != 1:
            raise SystemExit(f"{mutant.name}: expected the text once in {mutant.path}, "
                             f"found it {count} times (the code moved: update the mutant)")
        text = text.replace(old, new)
    file.write_text(text)
    return original


def _importer_caches(copy: Path, file: Path) -> list[Path]:
    """The kernel caches of the modules beside ``file`` that import from it. numba keys a
    cache on its own source file only: a kernel that inlines a function of ``file`` (e.g.
    ``reproject`` the fetch of ``resample``) would keep running the unpatched code."""
    dotted = ".".join(file.relative_to(copy).with_suffix("").parts)
    importers = [other.stem for other in file.parent.glob("*.py")
                 if other != file and f"from {dotted} import" in other.read_text()]
    cache = file.parent / "__pycache__"
    return [path for stem in importers for path in cache.glob(f"{stem}.*.nb[ic]")]


def plant(copy: Path, mutant: Mutant, full: bool) -> tuple[int, str, float]:
    file = copy / mutant.path
    stat = file.stat()
    cache = file.parent / "__pycache__"
    saved_cache = copy / ".plant-cache-backup"
    if cache.exists():
        shutil.copytree(cache, saved_cache, copy_function=shutil.copy2)
    for stale in _importer_caches(copy, file):  # restored with the rest of the cache below
        stale.unlink()
    original = _patch(file, mutant)
    try:
        return run_tests(copy, mutant.tests, full)
    finally:
        file.write_text(original)
        os.utime(file, ns=(stat.st_atime_ns, stat.st_mtime_ns))
        if saved_cache.exists():
            shutil.rmtree(cache, ignore_errors=True)
            shutil.move(saved_cache, cache)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--list", action="store_true", help="list the mutants and exit")
    parser.add_argument("--only", action="append", default=[], help="run this mutant")
    parser.add_argument("--owner", action="append", default=[],
                        help="run the mutants of this owner (filters, io, farm)")
    parser.add_argument("--full", action="store_true", help="run the whole suite per mutant")
    parser.add_argument("--tests", action="append", default=[],
                        help="run these test files instead of each mutant's own")
    parser.add_argument("--no-baseline", action="store_true", help="skip the baseline run")
    parser.add_argument("--keep", action="store_true", help="keep the copy of the tree")
    args = parser.parse_args(argv)
    chosen = [m for m in MUTANTS if (not args.only or m.name in args.only)
              and (not args.owner or m.owner in args.owner)]
    if args.tests:
        chosen = [dataclasses.replace(m, tests=tuple(args.tests)) for m in chosen]
    unknown = set(args.only) - {m.name for m in MUTANTS}
    if unknown:
        parser.error(f"unknown mutant(s): {', '.join(sorted(unknown))}")
    if args.list:
        for m in chosen:
            print(f"{m.name:24} {m.owner:8} {m.bug}  [{m.path}]")
        return 0
    copy = Path(tempfile.mkdtemp(prefix="svgf-mutants-"))
    try:
        print(f"copying the tree to {copy}", file=sys.stderr)
        copy_tree(copy)
        check_import_location(copy)
        if not args.no_baseline:
            tests = tuple(dict.fromkeys(t for m in chosen for t in m.tests))
            code, summary, seconds = run_tests(copy, tests, args.full)
            print(f"baseline: exit {code} in {seconds:.0f} s: {summary}", file=sys.stderr)
            if code != 0:
                print("the unpatched tree fails these tests: fix that first", file=sys.stderr)
                return 2
        rows, survived = [], []
        for mutant in chosen:
            code, summary, seconds = plant(copy, mutant, args.full)
            verdict = "caught" if code != 0 else "SURVIVED"
            if code == 0:
                survived.append(mutant.name)
            print(f"{mutant.name}: {verdict} ({seconds:.0f} s) {summary}", file=sys.stderr)
            rows.append(f"| {mutant.bug} | `{mutant.name}` | {mutant.owner} | {verdict} | "
                        f"{summary.replace('|', '/')[:110]} |")
        print("| planted bug | name | owner | result | first failure |")
        print("|---|---|---|---|---|")
        print("\n".join(rows))
        return 1 if survived else 0
    finally:
        if args.keep:
            print(f"kept {copy}", file=sys.stderr)
        else:
            shutil.rmtree(copy, ignore_errors=True)


if __name__ == "__main__":
    sys.exit(main())
