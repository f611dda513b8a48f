"""Mutation testing of svgf_cli/filters/, svgf_cli/io/ and svgf_cli/run/ with cosmic-ray.

cosmic-ray writes each mutant to disk and runs a test command, so the numba kernels are
mutated like any other code (mutmut 3 skips every decorated function, hence every
``@njit`` kernel; see docs/development.md). This driver keeps what makes that affordable:

* one cosmic-ray session (SQLite) per module, made by ``cosmic-ray init`` and narrowed by
  its ``cr-filter-operators`` filter (the operator set in ``EXCLUDED_OPERATORS``) and by
  ``skip_inert`` below (type hints, debug logging, ``__repr__``, numba compile options, the
  bare ``*`` of keyword-only parameters): those mutants are SKIPPED;
* a copy of the tree per package under ``.mutation/<package>/tree`` (the worktree is never
  mutated, and the io run and the filters run can go on side by side);
* a warm numba cache: after a baseline run the kernel caches are saved; before each mutant
  they are put back, and only the caches of the mutated module and of the filters modules
  that import it (numba freezes an imported function or constant into its caller's cache)
  are dropped, so a mutant recompiles only what it can change;
* per module, only the tests that exercise it, fastest first, with ``-x``;
* mutants run in a seeded random order across a package, so a run stopped by ``--minutes``
  has tested a uniform random sample; running again resumes where it stopped. A session
  is made again when its module's source changed (the mutants moved).

    .venv/bin/python tests/mutants/mutation.py run --package io --minutes 60
    .venv/bin/python tests/mutants/mutation.py run --package filters --module atrous
    .venv/bin/python tests/mutants/mutation.py report            # score + survivors
    .venv/bin/python tests/mutants/mutation.py show svgf_cli/io/exr.py:JOB_ID

``make mutation`` runs both packages. Equivalent mutants are listed in ``EQUIVALENT``
(module, function, operator, the original line, why) and leave the score's denominator.
Not collected by pytest (the file name does not start with ``test_``).
"""

from __future__ import annotations

import argparse
import ast
import hashlib
import json
import math
import os
import random
import shutil
import sqlite3
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
WORK = ROOT / ".mutation"

# One replacement per operator (as PIT's and mutmut's defaults): cosmic-ray replaces each
# binary operator with every other one and each comparison with every other one, 11 and 9
# variants a site, mostly type errors or duplicates of these. RemoveDecorator would turn a
# kernel into slow Python (same result, or a timeout). Regular expressions on operator names.
_KEPT_BINARY = ("Add_Sub", "Sub_Add", "Mul_Div", "Div_Mul", "FloorDiv_Mul", "Mod_Mul",
                "Pow_Mul", "LShift_RShift", "RShift_LShift", "BitAnd_BitOr", "BitOr_BitAnd",
                "BitXor_BitAnd")
_KEPT_COMPARISON = ("Lt_LtE", "Lt_GtE", "LtE_Lt", "LtE_Gt", "Gt_GtE", "Gt_LtE", "GtE_Gt",
                    "GtE_Lt", "Eq_NotEq", "NotEq_Eq", "Is_IsNot", "IsNot_Is", "In_NotIn",
                    "NotIn_In")
EXCLUDED_OPERATORS = (
    rf"core/ReplaceBinaryOperator_(?!(?:{'|'.join(_KEPT_BINARY)})$)",
    rf"core/ReplaceComparisonOperator_(?!(?:{'|'.join(_KEPT_COMPARISON)})$)",
    r"core/RemoveDecorator",
    r"core/Variable(Inserter|Replacer)",
)

FILTER_TESTS = (
    "tests/test_reference_stages.py",
    "tests/test_filters_stages.py",
    "tests/test_filters_atrous.py",
    "tests/test_filters_values.py",
    "tests/test_reference_denoiser.py",
    "tests/test_filters_signals.py",
    "tests/test_filters_scale.py",
    "tests/test_filters_antilag.py",
    "tests/test_filters_denoiser.py",
    "tests/test_filters_determinism_flags.py",
    "tests/test_filters_glossy.py",
    "tests/test_filters_bidirectional.py",
)
# The bidirectional kernels' own tests first (the rest of FILTER_TESTS never calls them).
_BIDIRECTIONAL_TESTS = ("tests/test_filters_bidirectional.py", *FILTER_TESTS[:-1])
_READ_TESTS = (
    "tests/test_io_source.py",
    "tests/test_io_signals.py",
    "tests/test_io_header.py",
    "tests/test_io_exr.py",
    "tests/test_io_layers.py",
    "tests/test_io_presets.py",
    "tests/test_io_colour.py",
    "tests/test_io_passthrough.py",
    "tests/test_inspect.py",
    "tests/test_cycles_conventions.py",
    "tests/test_runner_output.py",
    "tests/test_io_write_safety.py",
    "tests/test_cli_denoise.py",
    "tests/test_cli_ground_truth.py",
    "tests/robustness/test_fault_files.py",
    "tests/robustness/test_fault_values.py",
    "tests/robustness/test_fault_structure.py",
    "tests/robustness/test_fault_real_files.py",
)
_WRITE_TESTS = (
    "tests/test_io_write_safety.py",
    "tests/test_io_exr.py",
    "tests/test_runner_output.py",
    "tests/test_cli_denoise.py",
    "tests/test_farm_resume.py",
    "tests/robustness/test_fault_processes.py",
    "tests/robustness/test_fault_disk.py",
)
# Which tests exercise a module, fastest first (a killed mutant stops at its first failure).
MODULE_TESTS: dict[str, tuple[str, ...]] = {
    "svgf_cli/filters/params.py": ("tests/test_filters_params.py", *FILTER_TESTS),
    "svgf_cli/filters/bidirectional.py": _BIDIRECTIONAL_TESTS,
    "svgf_cli/filters/two_pass.py": _BIDIRECTIONAL_TESTS,
    "svgf_cli/filters/warm_start.py": ("tests/test_filters_warm_start.py",),
    "svgf_cli/filters/invert_motion.py": ("tests/test_filters_bidirectional.py",
                                          "tests/test_motion_next.py", *FILTER_TESTS[:-1]),
    "svgf_cli/io/colour.py": ("tests/test_io_colour.py", "tests/test_io_exr.py",
                              "tests/test_io_passthrough.py", "tests/test_cli_denoise.py"),
    "svgf_cli/io/patterns.py": ("tests/test_io_patterns.py", "tests/test_farm_plan.py",
                                "tests/test_cli_denoise.py", "tests/test_farm_chunks.py",
                                "tests/test_farm_resume.py"),
    "svgf_cli/io/layers.py": _READ_TESTS,
    "svgf_cli/io/exr.py": _READ_TESTS + ("tests/test_farm_resume.py",),
    "svgf_cli/io/source.py": _READ_TESTS,
    "svgf_cli/io/signals.py": ("tests/test_io_signals.py", "tests/test_cli_signals.py",
                               *_READ_TESTS),
    "svgf_cli/io/spill.py": ("tests/test_io_zipchunks.py", "tests/test_bidir_runs.py"),
    "svgf_cli/io/zipchunks.py": ("tests/test_io_zipchunks.py", "tests/test_io_memory.py",
                                 "tests/test_io_write_safety.py", "tests/test_bidir_runs.py"),
    "svgf_cli/io/output.py": ("tests/test_io_zipchunks.py", *_READ_TESTS),
    "svgf_cli/io/atomic.py": _WRITE_TESTS,
    "svgf_cli/io/lightlayers.py": ("tests/test_light_layers.py",),
    "svgf_cli/filters/composable.py": ("tests/test_light_layers.py",),
    "svgf_cli/filters/pass_shares.py": ("tests/test_light_layers.py",),
    "svgf_cli/filters/shares.py": ("tests/test_light_layers.py",),
    "svgf_cli/filters/jitter.py": ("tests/test_filters_jitter.py",),
    "svgf_cli/filters/id_stability.py": ("tests/test_filters_id_stability.py",),
    "svgf_cli/filters/emission_mean.py": ("tests/test_filters_emission_mean.py",),
    "svgf_cli/run/light.py": ("tests/test_light_layers.py",),
}
# The file driver (svgf_cli/run/, every module): its tests, fastest first.
_RUN_TESTS = ("tests/test_runner_tasks.py", "tests/test_runner_output.py",
              "tests/test_io_write_safety.py", "tests/test_cli_denoise.py",
              "tests/test_farm_runner.py",
              "tests/test_farm_chunks.py", "tests/test_farm_resume.py",
              "tests/test_cli_ground_truth.py",
              "tests/robustness/test_fault_files.py",
              "tests/robustness/test_fault_values.py",
              "tests/robustness/test_fault_structure.py",
              "tests/robustness/test_fault_processes.py",
              "tests/test_bidir_runs.py", "tests/test_bidir_memory.py")
# filters/stages/: the host side of each stage (what was the Denoiser's), no numba kernels.
PACKAGES = {"io": ("svgf_cli/io", "svgf_cli/run"),
            "filters": ("svgf_cli/filters", "svgf_cli/filters/stages")}
TIMEOUT_S = {"io": 180.0, "filters": 300.0}


@dataclass(frozen=True)
class Equivalent:
    module: str
    function: str | None  # None: module level
    operator: str
    line: str  # the original source line, stripped
    why: str


# Survivors that no test can kill: the mutant computes the same thing. Keyed by text, not
# by line number, so the list survives edits elsewhere in the file.
EQUIVALENT: tuple[Equivalent, ...] = (
    Equivalent("svgf_cli/filters/despike.py", "despike", "core/ReplaceComparisonOperator_Gt_GtE",
               "if d[x] > _ZERO and reference >= _ZERO and lum[x] > bound:",
               "d > 0 -> d >= 0: a background pixel's luminance is _NONE (-FLT_MAX) in the "
               "plane (pass 1), never above a bound >= 0, so it is left alone either way"),
    Equivalent("svgf_cli/filters/despike.py", "_neighbours", "core/ReplaceBinaryOperator_Add_Sub",
               "yy = y + dy",
               "y - dy over dy in -1..1 with every dx visits the same 8 neighbours (the offset "
               "set is symmetric) and takes their maximum, second maximum and agreeing mode "
               "bits, none of which depends on the order: the same bound"),
    Equivalent("svgf_cli/io/exr.py", "_assemble_frame", "core/NumberReplacer",
               'depth = values["depth"][0]',
               "[0] -> [-1]: the depth role is one plane (1, H, W), first and last are the same"),
    Equivalent("svgf_cli/io/exr.py", "ExrPart", "core/ReplaceFalseWithTrue",
               "tiled: bool = False",
               "a default never used: the one ExrPart(...) call passes tiled="),
    Equivalent("svgf_cli/io/atomic.py", "stale_temporaries", "core/ReplaceFalseWithTrue",
               "age = now - entry.stat(follow_symlinks=False).st_mtime",
               "stat vs lstat: svgf's temporaries are regular files, where both agree"),
    Equivalent("svgf_cli/io/exr.py", "ExrInfo", "core/NumberReplacer",
               "display_window: tuple[int, int, int, int] = (0, 0, 0, 0)",
               "a default never used: the one ExrInfo(...) call passes display_window="),
    Equivalent("svgf_cli/io/layers.py", "_expand_layer", "core/NumberReplacer",
               'if len(names) == width and (width > 1 or "." in names[0]):',
               "names[0] -> names[-1]: read only when len(names) == width == 1"),
    Equivalent("svgf_cli/io/exr.py", "_clean_role", "core/NumberReplacer",
               "return 0  # id: read as is (the mesh id is derived from it later)",
               "0 -> -1 for the id plane: its float plane is copied instead of shared, the "
               "values are the same (sharing only saves memory)"),
    Equivalent("svgf_cli/io/layers.py", "_suffix_index", "core/NumberReplacer",
               "for start in range(1, len(parts)):",
               "1 -> 0 adds each whole name as its own suffix: the empty prefix it yields "
               "matches only exact names, which _match_tuple returns before"),
    Equivalent("svgf_cli/io/source.py", "decode_source", "core/NumberReplacer",
               "path: str | os.PathLike[str], threads: int = 0, expected_parts: int | None = "
               "None", "default decode threads 0 -> 1: same pixels; both callers pass threads="),
    Equivalent("svgf_cli/run/output.py", "build_output", "core/NumberReplacer",
               "keep_only = {layer_alpha(names[0])} & set(part.channels)",
               "names[0] -> names[1]: the colour's three channels are one layer (one prefix "
               "in layers._match_tuple, or R,G,B), so their alpha name is the same"),
    Equivalent("svgf_cli/run/workers.py", "close", "core/NumberReplacer",
               "self._pending[1].result()",
               "[1] -> [0]: the task has no result(), the AttributeError is suppressed like a "
               "write error, and executor.shutdown(wait=True) still waits for the write"),
    Equivalent("svgf_cli/io/exr.py", "_keep_colour_part_only", "core/NumberReplacer",
               'anchor = colour[0] if colour else (resolved[resolved.signal_roles[0]] or ("",))[0]',
               "another channel or signal as anchor: a layer's channels share its alpha and "
               "part; with no colour layer the writer keeps only a bare A, never a layer's"),
    Equivalent("svgf_cli/io/exr.py", "_keep_colour_part_only", "core/NumberReplacer",
               "part = source.part_holding(anchor) or source.parts[0]",
               "fallback never taken: the anchor is a channel of the file (the colour's or "
               "the first signal's), so part_holding finds its part"),
    Equivalent("svgf_cli/io/patterns.py", "format_frame_spec", "core/ReplaceFalseWithTrue",
               "return FrameSet.framesToFrameRange(ordered, sort=False, compress=False)",
               "the frames are already sorted and unique (sorted(set(...))): sort and "
               "compress have nothing to do"),
    Equivalent("svgf_cli/io/output.py", "PreparedColour", "core/NumberReplacer",
               "nonfinite: int = 0  # NaN/Inf set to 0",
               "a default never used: both PreparedColour(...) calls pass nonfinite"),
    Equivalent("svgf_cli/io/output.py", "write", "core/ExceptionReplacer", "except OSError:",
               "never taken: the OpenEXR bindings report every write failure as RuntimeError "
               "(missing folder, full disk, RLIMIT_FSIZE: test_fault_disk.py)"),
    Equivalent("svgf_cli/io/spill.py", "read", "core/NumberReplacer", "part = exr.parts[0]",
               "[0] -> [-1]: a scratch file is written by Spill.write with one part"),
    Equivalent("svgf_cli/run/workers.py", "default_reader", "core/ReplaceTrueWithFalse",
               "def default_reader(path: Path, mapping: LayerMapping, *, passthrough: bool = True)"
               " -> ReadResult:",
               "a default never used: frame_reader, its one caller, passes passthrough="),
    Equivalent("svgf_cli/io/exr.py", "_scrub", "core/ReplaceComparisonOperator_GtE_Gt",
               "if math.isfinite(low) and math.isfinite(high) and (low >= 0 or not "
               "clamp_negative):",
               "fast path >= 0 -> > 0: a plane whose minimum is 0 takes the full scan, which "
               "finds nothing to fix: same values, same count, more time"),
    Equivalent("svgf_cli/io/signals.py", None, "core/ReplaceTrueWithFalse",
               "@dataclass(frozen=True)",
               "frozen off: only assignment and hashing differ, and a class that were "
               "assigned to or hashed would fail loudly (killed); the survivor is neither"),
    Equivalent("svgf_cli/io/signals.py", "_recipes", "core/ReplaceTrueWithFalse",
               "inside = EMISSION_IN_DIRECT.get(mapping.preset, True)",
               "a default never used: every AOV preset has an entry (test_io_layers.py) and "
               "build_mapping refuses other names"),
    Equivalent("svgf_cli/io/source.py", "subsampled", "core/ReplaceOrWithAnd",
               'f"{part.name or part.index}:{name}"',
               "dead code: SourceFile.subsampled has no caller (output.py lists subsampled "
               "channels itself)"),
    Equivalent("svgf_cli/io/exr.py", "_renormalise", "core/ReplaceComparisonOperator_Gt_GtE",
               "off = (length > 0) & (np.abs(length - 1.0) > 1e-5)",
               "> -> >= at the 1e-5 tolerance: a normal exactly 1e-5 off unit length is "
               "renormalised or kept, both within the tolerance (accepted, not observable)"),
    Equivalent("svgf_cli/io/exr.py", "read_frame", "core/NumberReplacer",
               'alpha=values["alpha"][0] if "alpha" in values else None,',
               "[0] -> [-1]: the alpha role is one plane (1, H, W), first and last are the same"),
    Equivalent("svgf_cli/io/patterns.py", "expand_inputs", "core/NumberReplacer",
               "pattern = SequencePattern.parse(inputs[0])",
               "[0] -> [-1]: read only when len(inputs) == 1"),
    Equivalent("svgf_cli/io/patterns.py", "parse", "core/NumberReplacer",
               'return cls(text, directory, name, "", 0, is_sequence=False)',
               "a plain file's padding is never read: path() and display() return its name "
               "before they look at it"),
    Equivalent("svgf_cli/io/patterns.py", "expand_inputs", "core/NumberReplacer",
               "raise InputError(reason, inputs[0])",
               "[0] -> [-1]: read only when len(inputs) == 1"),
    Equivalent("svgf_cli/io/signals.py", "compose_signals", "core/NumberReplacer",
               "albedo = role(recipe.albedo[0])",
               "[0] -> [-1]: read only when len(recipe.albedo) == 1"),
    Equivalent("svgf_cli/io/source.py", "subsampled", "core/ReplaceComparisonOperator_NotEq_Eq",
               "if channel.x_sampling != 1 or channel.y_sampling != 1",
               "dead code: SourceFile.subsampled has no caller (output.py lists subsampled "
               "channels itself)"),
    Equivalent("svgf_cli/io/source.py", "subsampled", "core/NumberReplacer",
               "if channel.x_sampling != 1 or channel.y_sampling != 1",
               "dead code: SourceFile.subsampled has no caller (output.py lists subsampled "
               "channels itself)"),
    Equivalent("svgf_cli/io/colour.py", "for_filter", "core/ReplaceComparisonOperator_GtE_Gt",
               "if min(self.weights) >= 0.0:",
               ">= 0 -> > 0: only a weight of exactly 0 (CIE XYZ's (0, 1, 0)) takes "
               "non_negative(), which gives back non-negative weights summing to 1 unchanged"),
    Equivalent("svgf_cli/io/signals.py", "__init__", "core/AddNot",
               "for role in (*term.light, *((term.colour,) if term.colour else ())):",
               "use counts only decide when a role plane is let go: an uncounted colour is let "
               "go early and gathered again: same values, its warnings deduplicated "
               "(test_a_pass_used_twice_is_cleaned_and_reported_once), more work"),
    Equivalent("svgf_cli/io/signals.py", "__init__", "core/ReplaceBinaryOperator_Add_Sub",
               "uses[role] = uses.get(role, 0) + 1",
               "+1 -> -1: a role plane is let go later (or early and gathered again, as "
               "above): same values, other memory"),
    Equivalent("svgf_cli/run/workers.py", "close", "core/AddNot",
               "if self._pending is not None:",
               "either way executor.shutdown(wait=True) waits for the write and its result "
               "is discarded (suppressed); close() is the last call on the object"),
    Equivalent("svgf_cli/io/signals.py", "_recipes", "core/ReplaceTrueWithFalse",
               "divided = LOBE_LIGHT_DIVIDED.get(mapping.preset, True)",
               "a default never used: every AOV preset has an entry (test_io_layers.py) and "
               "build_mapping refuses other names"),
    Equivalent("svgf_cli/filters/reproject.py", "_reproject_rows",
               "core/ReplaceComparisonOperator_Lt_LtE", "if box_mask < 0:",
               "< 0 -> <= 0: -1 marks a 3x3 mask not yet computed (shared by the signals); "
               "recomputing a mask of 0 gives 0 again"),
    Equivalent("svgf_cli/filters/variance.py", "spatial_variance", "core/AddNot",
               "while x < width and not needed[x]:",
               "skip loop off: runs start earlier, but the run kernel skips pixels with "
               "enough history, so the same pixels are written with the same values"),
    Equivalent("svgf_cli/filters/atrous.py", "_atrous_row", "core/NumberReplacer",
               "if count <= 0:",
               "<= 0 -> <= -1: counts are >= 0 (sorted bounds) and _segment loops range(count)"),
    Equivalent("svgf_cli/filters/stages/reproject.py", "run", "core/NumberReplacer",
               "history_length.fill(0.0)",
               "0 -> -1: accumulation reuses history only where h_prev > 0; both give h = 1"),
    Equivalent("svgf_cli/io/source.py", "data_window", "core/NumberReplacer",
               "return (int(low[0]), int(low[1]), int(high[0] - low[0] + 1), int(high[1] - "
               "low[1] + 1))",
               "an index of the x or y origin: SourcePart.data_window's one reader (exr.py's "
               "shape check) unpacks only width and height (a width/height mutant fails "
               "that check on every read)"),
    Equivalent("svgf_cli/filters/variance.py", "spatial_variance",
               "core/ReplaceComparisonOperator_Lt_GtE",
               "while x < width and x - last <= RUN_GAP:",
               "run merging off: every needed pixel becomes its own run, and the run kernel "
               "sums each pixel's taps in the same order: bit-identical values (checked on "
               "the reference test's inputs), more calls"),
    Equivalent("svgf_cli/io/signals.py", "__init__", "core/NumberReplacer",
               "uses[role] = uses.get(role, 0) + 1",
               "a count off by one either way: a role plane is let go later, never, or early "
               "and gathered again (as the +1 -> -1 entry): same values, other memory"),
    Equivalent("svgf_cli/io/signals.py", "_gradient_channels", "core/NumberReplacer",
               'prefix = mask[0][: -len("gradient.mask")]',
               "[0] -> [-1]: match_channels of one wanted name returns one channel"),
    Equivalent("svgf_cli/io/exr.py", "_clean_role", "core/NumberReplacer",
               "return _clean_depth(data[0], path, warnings)",
               "[0] -> [-1]: the depth role is one plane (1, H, W), first and last are the same"),
    Equivalent("svgf_cli/io/patterns.py", None, "core/ReplaceTrueWithFalse",
               "@dataclass(frozen=True)",
               "frozen off: only attribute assignment and hashing differ; no code assigns to "
               "or hashes a SequencePattern (either would fail loudly, killed)"),
    Equivalent("svgf_cli/run/workers.py", "close", "core/ReplaceTrueWithFalse",
               "self._executor.shutdown(wait=True, cancel_futures=True)",
               "the read-ahead holds at most one prefetch, usually already running (then "
               "cancel cannot stop it either); its result is dropped unread either way"),
    Equivalent("svgf_cli/run/filter.py", "save_history", "core/ReplaceOrWithAnd",
               "if self.size is None or self._stats.last_frame is None:",
               "or -> and: the same frame sets both (admit, then process) and save_history runs "
               "only after the loop: both are None or both are set"),
    Equivalent("svgf_cli/io/layers.py", "_match_tuple", "core/ReplaceComparisonOperator_Gt_GtE",
               "if len(hits) > 1:",
               "> 1 -> >= 1: len(hits) == 1 has returned just above, so both read len >= 2"),
    Equivalent("svgf_cli/filters/stages/reproject.py", "gradient_samples",
               "core/NumberReplacer",
               "mask = np.where(finite & (gradient.mask > 0), F32(1.0), F32(0.0))",
               "the mask's one reader (_gradient_row_sums) tests only mask > 0: any positive "
               "value for a sample, 0 (or below) for none"),
    Equivalent("svgf_cli/filters/stages/history_clamp.py", "run", "core/ReplaceFalseWithTrue",
               "for glossy in temporal.glossy or (False,) * len(temporal.names)]",
               "fallback never taken: the stage runs only on a reprojected frame, whose "
               "TemporalState (stages/reproject.py) has one glossy flag per signal, and a "
               "frame has at least one signal"),
    Equivalent("svgf_cli/filters/variance.py", "spatial_variance",
               "core/ReplaceComparisonOperator_Lt_LtE", "while x < width:",
               "< -> <=: at x == width the skip loop does nothing and `if x >= width: break` "
               "leaves, as the loop test would have"),
    Equivalent("svgf_cli/io/signals.py", "_sum", "core/NumberReplacer", "return planes[0]",
               "[0] -> [-1]: read only when len(planes) == 1"),
    Equivalent("svgf_cli/io/signals.py", "per_lobe", "core/ReplaceComparisonOperator_Eq_NotEq",
               "elif lobe == specular[0]:",
               "the merged specular signal is built from the list, not the lobe, and put at "
               "the second glossy lobe instead of the first: glossy and transmission are "
               "adjacent in LOBES (the order of lobes.present), so the order is the same"),
    Equivalent("svgf_cli/io/output.py", "write_output", "core/NumberReplacer", "threads: int = 0,",
               "a default never used: write_output's one caller (run.workers.frame_writer) passes "
               "threads="),
    Equivalent("svgf_cli/io/signals.py", "compose_signals", "core/AddNot", "if fresh:",
               "not fresh (both sites): the next term is added, or the emission subtracted, "
               "in the first term's role plane instead of a new array: the same values; every "
               "plan reads each light role once and lets the plane go after it, so nothing "
               "reads the changed plane (a fallback plan gathers it again)"),
    Equivalent("svgf_cli/io/signals.py", "__call__", "core/NumberReplacer",
               "self._uses[role] -= 1",
               "a use count that does not fall (or falls by two): the role plane is let go "
               "never, or early and gathered again: same values, other memory"),
    Equivalent("svgf_cli/io/colour.py", "rgb_to_xyz_matrix",
               "core/ReplaceComparisonOperator_Lt_LtE", "if abs(np.linalg.det(primaries)) < 1e-9:",
               "< -> <= at the degeneracy tolerance: primaries whose determinant is exactly "
               "1e-9 are degenerate either way (a tolerance boundary, not observable)"),
    Equivalent("svgf_cli/filters/atrous.py", "_atrous_rows", "core/NumberReplacer",
               "sums = np.empty((3, 5, CHUNK), dtype=np.float32)",
               "3 -> 4: a fourth scratch slice that is never written or read (_atrous_row "
               "fills and reads back sums[t] for t < 2, _atrous_row3 sums[s] for s < 3)"),
    Equivalent("svgf_cli/filters/stages/reproject.py", "gradient_samples",
               "core/NumberReplacer",
               "samples.append((mask, np.where(finite, gradient.previous, F32(0.0)),",
               "the stand-in for a non-finite sample only needs to be finite: its mask is 0 and "
               "_gradient_row_sums, the only reader, multiplies every term by the mask"),
    Equivalent("svgf_cli/filters/stages/reproject.py", "gradient_samples",
               "core/NumberReplacer",
               "np.where(finite, gradient.current, F32(0.0))))",
               "the stand-in for a non-finite sample only needs to be finite: its mask is 0 and "
               "_gradient_row_sums, the only reader, multiplies every term by the mask"),
    Equivalent("svgf_cli/filters/variance.py", "_needed_row", "core/NumberReplacer",
               "largest = np.uint8(0)",
               "0 -> 1: every row is then scanned for runs of needed pixels, and a row with "
               "none yields no run: same pixels written, more time"),
    Equivalent("svgf_cli/filters/variance.py", "_spatial_variance_run", "core/NumberReplacer",
               "if count <= 0:",
               "<= 0 -> <= -1: a tap column with count 0 then runs loops of range(0) over "
               "empty slices: nothing is added"),
)


def modules_of(package: str) -> list[str]:
    found: list[str] = []
    for entry in PACKAGES[package]:
        path = ROOT / entry
        files = sorted(path.glob("*.py")) if path.is_dir() else [path]
        found += [str(f.relative_to(ROOT)) for f in files if f.name != "__init__.py"]
    return found


def tests_for(module: str) -> tuple[str, ...]:
    if module.startswith("svgf_cli/run/"):
        return _RUN_TESTS
    return MODULE_TESTS.get(module, FILTER_TESTS if module.startswith("svgf_cli/filters/")
                            else _READ_TESTS)


# --- numba caches ------------------------------------------------------------------------

def filters_importers(tree: Path, module: str) -> set[str]:
    """The filters modules whose numba caches may hold code of `module` (it and its importers,
    transitively): numba compiles an imported kernel or constant into its caller."""
    folder = tree / "svgf_cli/filters"
    imports: dict[str, set[str]] = {}
    for file in folder.glob("*.py"):
        names: set[str] = set()
        for node in ast.walk(ast.parse(file.read_text())):
            if isinstance(node, ast.ImportFrom) and node.module:
                if node.module.startswith("svgf_cli.filters."):
                    names.add(node.module.rsplit(".", 1)[1])
                elif node.module == "svgf_cli.filters":
                    names.update(alias.name for alias in node.names)
            elif isinstance(node, ast.ImportFrom) and node.level and node.module:
                names.add(node.module)
        imports[file.stem] = names
    stem = Path(module).stem
    if not module.startswith("svgf_cli/filters/") or module.startswith("svgf_cli/filters/stages/"):
        return set()  # a stage module holds no kernels (its stem may be a kernel module's)
    affected, grew = {stem}, True
    while grew:
        grew = False
        for name, used in imports.items():
            if name not in affected and used & affected:
                affected.add(name)
                grew = True
    return affected


def _cache_files(tree: Path) -> list[Path]:
    return sorted(tree.glob("svgf_*/**/__pycache__/*.nb[ic]"))


def save_caches(tree: Path, saved: Path) -> None:
    """Keep the warm kernel caches and the source modification times they are stamped with."""
    shutil.rmtree(saved, ignore_errors=True)
    saved.mkdir(parents=True)
    for cache in _cache_files(tree):
        target = saved / cache.relative_to(tree)
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(cache, target)
    stamps = {str(p.relative_to(tree)): p.stat().st_mtime_ns
              for p in tree.glob("svgf_*/**/*.py")}
    (saved / "mtimes.json").write_text(json.dumps(stamps))


def restore_caches(tree: Path, saved: Path, mutated: str) -> None:
    """Warm caches for every module but the mutated one and its importers."""
    dropped = filters_importers(tree, mutated)
    stamps = json.loads((saved / "mtimes.json").read_text())
    for name, mtime in stamps.items():
        source = tree / name
        if name != mutated and source.exists() and source.stat().st_mtime_ns != mtime:
            os.utime(source, ns=(mtime, mtime))  # restored by cosmic-ray: same text
    for cache in _cache_files(tree):
        cache.unlink()
    for cache in _cache_files(saved):
        relative = cache.relative_to(saved)
        stem = relative.name.split(".", 1)[0]
        if relative.parts[:2] == ("svgf_cli", "filters") and stem in dropped:
            continue
        target = tree / relative
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(cache, target)


# --- what cannot matter --------------------------------------------------------------------

# Debug logging only (the standard logging module): the warnings svgf prints to users
# (``progress.warning``: the file and the problem) are behaviour, and are mutated.
_LOGGERS = {"log", "logger", "_log", "_logger", "LOG", "logging"}
# numba compile options (parallel, cache, nogil, boundscheck, inline) change speed, not
# results: the kernels are bit-identical across thread counts (test_filters_denoiser.py).
_NUMBA_DECORATORS = {"njit", "jit", "noalias_njit", "vectorize", "guvectorize"}


def inert_spans(source: str) -> list[tuple[tuple[int, int], tuple[int, int], str]]:
    """Source spans whose mutation cannot change behaviour: type hints (the modules use
    ``from __future__ import annotations``), debug logging calls, ``__repr__``, numba
    compile options."""
    spans = []

    def span(node: ast.AST, why: str) -> None:
        spans.append(((node.lineno, node.col_offset), (node.end_lineno, node.end_col_offset),
                      why))

    for node in ast.walk(ast.parse(source)):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            if node.name in ("__repr__", "__str__"):
                span(node, "__repr__")
            if node.returns is not None:
                span(node.returns, "type hint")
            every = node.args.posonlyargs + node.args.args + node.args.kwonlyargs
            every += [a for a in (node.args.vararg, node.args.kwarg) if a is not None]
            for arg in every:
                if arg.annotation is not None:
                    span(arg.annotation, "type hint")
        elif isinstance(node, ast.AnnAssign):
            span(node.annotation, "type hint")
        elif isinstance(node, ast.Call):
            func = node.func
            if isinstance(func, ast.Attribute) and isinstance(func.value, ast.Name) \
                    and func.value.id in _LOGGERS:
                span(node, "logging")
            elif isinstance(func, ast.Name) and (
                    func.id in _NUMBA_DECORATORS
                    or (func.id == "dict" and any(k.arg == "cache" for k in node.keywords))):
                span(node, "numba compile options")
    return spans


def _keyword_only_marker(lines: list[str], mutation) -> bool:
    """cosmic-ray reads the bare ``*`` of a signature (keyword-only parameters follow) as a
    multiplication; ``/`` there only makes the earlier parameters positional-only, an API
    change a caller sees at once, never a change of what the code computes."""
    if not mutation.operator_name.startswith("core/ReplaceBinaryOperator_Mul_"):
        return False
    row, col = mutation.start_pos
    text = lines[row - 1] if 0 < row <= len(lines) else ""
    return text[col:col + 1] == "*" and text[col + 1:].lstrip()[:1] in (",", ")")


def skip_inert(db_path: Path, module_file: Path) -> int:
    """Mark the mutants inside `inert_spans` SKIPPED in the session (a cosmic-ray filter);
    also those already run, so that a rule added later applies to earlier results."""
    from cosmic_ray.work_db import WorkDB, use_db
    from cosmic_ray.work_item import WorkerOutcome, WorkResult

    source = module_file.read_text()
    spans, lines = inert_spans(source), source.splitlines()
    skipped, released = 0, []
    with use_db(str(db_path), WorkDB.Mode.open) as db:
        results = dict(db.results)
        for item in list(db.work_items):
            mutation = item.mutations[0]
            start, end = tuple(mutation.start_pos), tuple(mutation.end_pos)
            why = next((w for s, e, w in spans if s <= start and end <= e), None)
            if why is None and _keyword_only_marker(lines, mutation):
                why = "keyword-only marker"
            earlier = results.get(item.job_id)
            if why:
                db.set_result(item.job_id, WorkResult(
                    output=f"excluded: {why}", worker_outcome=WorkerOutcome.SKIPPED))
                skipped += 1
            elif earlier is not None and (earlier.output or "").startswith("excluded: "):
                released.append(item.job_id)  # a rule since narrowed: test it after all
    if released:
        with sqlite3.connect(db_path) as connection:
            connection.executemany("DELETE FROM work_results WHERE job_id = ?",
                                   [(job,) for job in released])
    return skipped


# --- sessions ------------------------------------------------------------------------------

def _digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()[:16]


def session_path(package: str, module: str) -> Path:
    return WORK / package / "sessions" / (module.replace("/", "_") + ".sqlite")


def _config_text(module: str, package: str) -> str:
    excluded = ", ".join(json.dumps(e) for e in EXCLUDED_OPERATORS)
    command = f"{sys.executable} tests/mutants/mutation.py _pytest {module}"
    return (f'[cosmic-ray]\nmodule-path = "{module}"\ntimeout = {TIMEOUT_S[package]}\n'
            f'excluded-modules = []\ntest-command = "{command}"\n\n'
            f'[cosmic-ray.distributor]\nname = "local"\n\n'
            f'[cosmic-ray.filters.operators-filter]\nexclude-operators = [{excluded}]\n')


def ensure_session(package: str, module: str) -> Path:
    """The module's session, made again when its source or the operator set changed."""
    db = session_path(package, module)
    config = db.with_suffix(".toml")
    stamp = db.with_suffix(".source")
    text = _config_text(module, package)
    key = _digest(ROOT / module) + " " + hashlib.sha256(text.encode()).hexdigest()[:16]
    if db.exists() and stamp.exists() and stamp.read_text() == key:
        skip_inert(db, ROOT / module)  # the rules may have grown since the session was made
        return db
    db.parent.mkdir(parents=True, exist_ok=True)
    earlier = _tested_by_diff(db) if db.exists() else {}
    db.unlink(missing_ok=True)
    config.write_text(text)
    bin_dir = Path(sys.executable).parent
    subprocess.run([bin_dir / "cosmic-ray", "init", config, db], cwd=ROOT, check=True)
    subprocess.run([bin_dir / "cr-filter-operators", db, config], cwd=ROOT, check=True)
    skipped = skip_inert(db, ROOT / module)
    carried = _carry_results(db, ROOT / module, earlier)
    print(f"{module}: session made ({skipped} inert mutants skipped, {carried} results "
          f"carried over from the previous session)", file=sys.stderr)
    stamp.write_text(key)
    return db


def _diff_key(operator: str, function: str | None, diff: str) -> tuple[str, str, str]:
    """A mutant by what it does to the text: its operator, its function and its diff without
    line numbers (the changed line and three lines of context either side)."""
    body = [line for line in diff.splitlines()
            if not line.startswith(("--- ", "+++ ", "@@"))]
    return (operator, function or "", "\n".join(body))


def _tested_by_diff(db_path: Path) -> dict[tuple[str, str, str], list]:
    """The tested mutants of a session about to be made again, by ``_diff_key``."""
    from cosmic_ray.work_db import WorkDB, use_db
    from cosmic_ray.work_item import WorkerOutcome

    found: dict[tuple[str, str, str], list] = {}
    with use_db(str(db_path), WorkDB.Mode.open) as db:
        results = dict(db.results)
        for item in db.work_items:
            result = results.get(item.job_id)
            if result is None or result.worker_outcome != WorkerOutcome.NORMAL or not result.diff:
                continue
            mutation = item.mutations[0]
            key = _diff_key(mutation.operator_name, mutation.definition_name, result.diff)
            found.setdefault(key, []).append(result)
    return found


def _carry_results(db_path: Path, module_file: Path, earlier: dict) -> int:
    """Give a new session's mutants the results of the same mutants in the previous session
    of an edited module: same operator, same function, same diff (a mutant whose line or
    context changed is tested again). Carried survivors are retested by ``--survivors``."""
    if not earlier:
        return 0
    import cosmic_ray.plugins
    from cosmic_ray.mutating import _make_diff, mutate_code
    from cosmic_ray.work_db import WorkDB, use_db

    source = module_file.read_text()
    wanted = {(operator, function) for operator, function, _ in earlier}
    carried = 0
    with use_db(str(db_path), WorkDB.Mode.open) as db:
        results = dict(db.results)
        for item in list(db.work_items):
            mutation = item.mutations[0]
            if item.job_id in results or \
                    (mutation.operator_name, mutation.definition_name or "") not in wanted:
                continue
            operator = cosmic_ray.plugins.get_operator(mutation.operator_name)(
                **(getattr(mutation, "operator_args", None) or {}))
            mutated = mutate_code(source, operator, mutation.occurrence)
            if mutated is None:
                continue
            diff = "\n".join(_make_diff(source, mutated, mutation.module_path))
            same = earlier.get(_diff_key(mutation.operator_name, mutation.definition_name, diff))
            if same:
                db.set_result(item.job_id, same.pop(0))
                carried += 1
    return carried


def prepare_tree(package: str) -> Path:
    """A fresh copy of the tree (with warm caches) for this package's run."""
    sys.path.insert(0, str(ROOT / "tests/mutants"))
    from plant import copy_tree

    tree = WORK / package / "tree"
    shutil.rmtree(tree, ignore_errors=True)
    copy_tree(tree)
    return tree


def _environment(tree: Path) -> None:
    os.environ["PYTHONPATH"] = str(tree)
    os.environ["PYTHONDONTWRITEBYTECODE"] = "1"
    os.environ["SVGF_MUTATION_SAVED"] = str(WORK / os.environ["SVGF_MUTATION_PACKAGE"]
                                            / "saved-caches")


def baseline(tree: Path, package: str, modules: list[str]) -> None:
    tests = list(dict.fromkeys(t for m in modules for t in tests_for(m)))
    start = time.perf_counter()
    done = subprocess.run([sys.executable, "-m", "pytest", "-x", "-q", "-p", "no:cacheprovider",
                           *tests], cwd=tree, capture_output=True, text=True)
    seconds = time.perf_counter() - start
    tail = done.stdout.strip().splitlines()[-1:] or [done.stderr[-300:]]
    print(f"baseline {package}: exit {done.returncode} in {seconds:.0f} s: {tail[0]}",
          file=sys.stderr)
    if done.returncode != 0:
        raise SystemExit("the unmutated tree fails its tests: fix that first")
    save_caches(tree, WORK / package / "saved-caches")


def run(package: str, only: list[str], minutes: float, seed: int, survivors: bool) -> None:
    """Test the pending mutants (or, with `survivors`, test the survivors again: after adding
    tests) in the seeded order, until done or `minutes` have passed."""
    from cosmic_ray.mutating import mutate_and_test
    from cosmic_ray.work_db import WorkDB, use_db
    from cosmic_ray.work_item import TestOutcome

    modules = [m for m in modules_of(package) if not only or Path(m).stem in only]
    sessions = {m: ensure_session(package, m) for m in modules}
    pending = []
    for module, db_path in sessions.items():
        with use_db(str(db_path), WorkDB.Mode.open) as db:
            results = dict(db.results)
            if survivors:
                again = {job for job, r in results.items()
                         if r.test_outcome == TestOutcome.SURVIVED}
                pending += [(module, item) for item in db.work_items if item.job_id in again
                            and not equivalent_reason(module, item.mutations[0])]
            else:
                pending += [(module, item) for item in db.work_items
                            if item.job_id not in results]
    order = random.Random(seed)
    pending.sort(key=lambda mi: mi[1].job_id)
    order.shuffle(pending)
    print(f"{package}: {len(pending)} mutants pending", file=sys.stderr)
    if not pending:
        return
    os.environ["SVGF_MUTATION_PACKAGE"] = package
    tree = prepare_tree(package)
    _environment(tree)
    baseline(tree, package, modules)
    deadline = time.monotonic() + minutes * 60 if minutes else math.inf
    os.chdir(tree)
    log = (WORK / package / "run.log").open("a")
    for count, (module, item) in enumerate(pending, 1):
        if time.monotonic() > deadline:
            print(f"{package}: stopped after {minutes} min; run again to resume",
                  file=sys.stderr)
            break
        config = session_path(package, module).with_suffix(".toml").read_text()
        command = config.split('test-command = "', 1)[1].split('"', 1)[0]
        start = time.perf_counter()
        cpu = os.times()
        result = mutate_and_test(item.mutations, command, TIMEOUT_S[package])
        wall = time.perf_counter() - start
        after = os.times()
        child_cpu = (after.children_user - cpu.children_user
                     + after.children_system - cpu.children_system)
        with use_db(str(session_path(package, module)), WorkDB.Mode.open) as db:
            db.set_result(item.job_id, result)
        outcome = result.test_outcome.value if result.test_outcome else result.worker_outcome.value
        mutation = item.mutations[0]
        log.write(json.dumps({"module": module, "job": item.job_id, "outcome": outcome,
                              "operator": mutation.operator_name,
                              "line": mutation.start_pos[0], "wall_s": round(wall, 1),
                              "cpu_s": round(child_cpu, 1)}) + "\n")
        log.flush()
        print(f"[{count}/{len(pending)}] {module}:{mutation.start_pos[0]} "
              f"{mutation.operator_name}: {outcome} ({wall:.0f} s)", file=sys.stderr)


def run_module_tests(module: str) -> int:
    """The test command of one mutant (run by cosmic-ray inside the tree copy)."""
    tree = Path.cwd()
    restore_caches(tree, Path(os.environ["SVGF_MUTATION_SAVED"]), module)
    return subprocess.run([sys.executable, "-m", "pytest", "-x", "-q", "-p", "no:cacheprovider",
                           *tests_for(module)]).returncode


# --- report --------------------------------------------------------------------------------

def _original_line(module: str, line: int) -> str:
    lines = (ROOT / module).read_text().splitlines()
    return lines[line - 1].strip() if 0 < line <= len(lines) else ""


def equivalent_reason(module: str, mutation) -> str | None:
    line = _original_line(module, mutation.start_pos[0])
    for eq in EQUIVALENT:
        if (eq.module, eq.function, eq.operator, eq.line) == (
                module, mutation.definition_name, mutation.operator_name, line):
            return eq.why
    return None


def collect(package: str) -> dict:
    """Per module: how many mutants of each outcome; the survivors and equivalents."""
    from cosmic_ray.work_db import WorkDB, use_db
    from cosmic_ray.work_item import TestOutcome, WorkerOutcome

    tallies: dict[str, dict[str, int]] = {}
    survivors, equivalents = [], []
    for module in modules_of(package):
        db_path = session_path(package, module)
        if not db_path.exists():
            continue
        tally = tallies[module] = dict.fromkeys(
            ("operator set", "inert", "pending", "killed", "timeout", "survived",
             "equivalent"), 0)
        with use_db(str(db_path), WorkDB.Mode.open) as db:
            results = dict(db.results)
            for item in db.work_items:
                result = results.get(item.job_id)
                mutation = item.mutations[0]
                if result is None:
                    tally["pending"] += 1
                elif result.worker_outcome in (WorkerOutcome.SKIPPED, WorkerOutcome.NO_TEST):
                    inert = (result.output or "").startswith("excluded: ")
                    tally["inert" if inert else "operator set"] += 1
                elif result.test_outcome == TestOutcome.SURVIVED:
                    why = equivalent_reason(module, mutation)
                    entry = (module, item.job_id, mutation, result.diff, why)
                    tally["equivalent" if why else "survived"] += 1
                    (equivalents if why else survivors).append(entry)
                elif result.output == "timeout":
                    tally["timeout"] += 1
                else:  # a failing test, or a mutant that cannot even be imported/compiled
                    tally["killed"] += 1
    return {"tallies": tallies, "survivors": survivors, "equivalents": equivalents}


def _group(module: str) -> str:
    return module.rsplit("/", 1)[0] + "/"


def _wilson(k: int, n: int, z: float = 1.96) -> tuple[float, float]:
    if n == 0:
        return (0.0, 1.0)
    p = k / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return (centre - half, centre + half)


def report(packages: list[str], diffs: bool) -> None:
    """Score per package (killed / (killed + survived); timeouts count as killed, equivalent
    mutants and exclusions are left out), with a 95% Wilson interval for a partial run."""
    print("| package | mutants | excluded (inert) | tested | killed | timeout | survived | "
          "equivalent | pending | score | 95% interval |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    collected = {p: collect(p) for p in packages}
    groups: dict[str, dict[str, int]] = {}
    for data in collected.values():
        for module, tally in data["tallies"].items():
            group = groups.setdefault(_group(module), dict.fromkeys(tally, 0))
            for key, value in tally.items():
                group[key] += value
    for name, t in groups.items():
        killed = t["killed"] + t["timeout"]
        scored = killed + t["survived"]
        mutants = sum(t.values()) - t["operator set"]
        low, high = _wilson(killed, scored)
        score = f"{killed}/{scored} = {100 * killed / scored:.1f}%" if scored else "-"
        print(f"| `{name}` | {mutants} | {t['inert']} | {scored + t['equivalent']} | "
              f"{t['killed']} | {t['timeout']} | {t['survived']} | {t['equivalent']} | "
              f"{t['pending']} | {score} | {100 * low:.1f}-{100 * high:.1f}% |")
    for package in packages:
        log = WORK / package / "run.log"
        rows = [json.loads(line) for line in log.read_text().splitlines()] if log.exists() else []
        for outcome in ("killed", "survived"):
            chosen = [r for r in rows if r["outcome"] == outcome]
            if chosen:
                wall = sum(r["wall_s"] for r in chosen) / len(chosen)
                cpu = sum(r["cpu_s"] for r in chosen) / len(chosen)
                print(f"{package}: {len(chosen)} {outcome} mutants, mean {wall:.0f} s wall, "
                      f"{cpu:.0f} s CPU (user+sys) each")
    for package, data in collected.items():
        for title, entries in (("survivors", data["survivors"]),
                               ("equivalent", data["equivalents"])):
            if not entries:
                continue
            print(f"\n{package} {title}:")
            for module, job, mutation, diff, why in entries:
                line = _original_line(module, mutation.start_pos[0])
                print(f"- {module}:{mutation.start_pos[0]} {mutation.definition_name} "
                      f"{mutation.operator_name} [{job}] `{line}`" + (f": {why}" if why else ""))
                if diffs and diff:
                    changed = [d for d in diff.splitlines()[2:]
                               if d[:1] in "+-" and d.strip() not in "+-"]
                    print("\n".join("    " + d for d in changed))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)
    run_parser = sub.add_parser("run", help="test pending mutants (resumes)")
    run_parser.add_argument("--package", action="append", choices=sorted(PACKAGES))
    run_parser.add_argument("--module", action="append", default=[],
                            help="only this module (file stem, e.g. exr)")
    run_parser.add_argument("--minutes", type=float, default=0.0,
                            help="stop after this long (0: run them all)")
    run_parser.add_argument("--seed", type=int, default=15)
    run_parser.add_argument("--survivors", action="store_true",
                            help="test the surviving mutants again (after adding tests)")
    report_parser = sub.add_parser("report", help="score and survivors")
    report_parser.add_argument("--package", action="append", choices=sorted(PACKAGES))
    report_parser.add_argument("--diff", action="store_true", help="show each survivor's diff")
    internal = sub.add_parser("_pytest", help=argparse.SUPPRESS)
    internal.add_argument("module")
    args = parser.parse_args(argv)
    if args.command == "_pytest":
        return run_module_tests(args.module)
    packages = args.package or ["io", "filters"]
    if args.command == "run":
        for package in packages:
            run(package, args.module, args.minutes, args.seed, args.survivors)
    report(packages, getattr(args, "diff", False))
    return 0


if __name__ == "__main__":
    sys.exit(main())
