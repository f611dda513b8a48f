"""Bit-identity proof for refactors: hash every output of `svgf denoise` in every mode.

What it proves: two source trees (say, before and after a refactor of the host layer)
write the same pixels, bit for bit, for every bundled sequence and every run mode (causal
presets, split chunks with a bounded and a full warm-up, ``--chunk-size``, a local Dask
cluster, ``--bidirectional`` alone, chunked and resumed, ``--debug-aovs``, ``--taa``,
``--colour-only --float``, ``--skip-existing`` resume, ``--save-history``/``--load-history``).

Each case runs ``python -m svgf_cli denoise ...`` in a subprocess whose ``PYTHONPATH`` starts
with ``--tree`` (its working folder is a temporary one, so neither the current folder nor the
editable install can shadow the tree; this is checked at start, in a Dask worker too when a
Dask case runs). The inputs are always this repository's ``testdata/`` (``--data``), so the
input paths recorded in the outputs are the same for both trees. For every output file, per
part, it hashes (sha256):

* ``pixels/<part>/<channel>``: the channel's raw pixel bytes in its stored type (with its
  dtype, shape and sampling);
* ``header/<part>/<attribute>``: every header attribute that is not ``svgf/*``;
* ``metadata/<part>/<attribute>``: the ``svgf/*`` attributes: those the tool writes
  (``svgf_cli/run/output.py`` ``output_attributes``: ``svgf/version``, ``svgf/preset``,
  ``svgf/params``, ``svgf/frame``, ``svgf/input``, ``svgf/warmup``, ``svgf/kind``) and the
  inputs' own ``svgf/*`` keys the writer copies; they may legitimately change in a refactor
  (a new parameter in ``svgf/params``), so they are reported apart from pixels;
* in ``--save-history`` files (npz): ``history/<array>`` for the filter state arrays and
  ``metadata/<array>`` for the ``svgf_*`` bookkeeping.

The JSON is ``{case: {file: {key: sha256}}}`` (case = ``SEQUENCE:MODE``), plus a ``__run__``
entry (tree, timings) that comparisons ignore.

Run (from the repository root; the first run of a tree compiles its numba kernels)::

    nice -n 10 .venv/bin/python bench/hash_outputs.py --tree /tmp/pristine --out /tmp/base.json
    nice -n 10 .venv/bin/python bench/hash_outputs.py --compare /tmp/base.json
    .venv/bin/python bench/hash_outputs.py --only 'seq:*' --only '*:bidir' --compare /tmp/base.json
    .venv/bin/python bench/hash_outputs.py --compare /tmp/base.json --current /tmp/new.json
    .venv/bin/python bench/hash_outputs.py --list [--all-modes]

By default every mode runs on ``seq``, ``lag/glossy`` and ``cycles/roll`` and the causal
default and ``--bidirectional`` on the other sequences (60 cases, about 5 minutes warm on
two shared cores); ``--all-modes`` runs every mode on every sequence (144 cases, 7 to 10
minutes). ``testdata/seq_box`` holds only references (its inputs are ``seq``'s), so it is
no case of its own.

``--compare`` exits 1 when any case differs (pixels, header, history, files or metadata;
``--pixels-only`` lets metadata-only differences pass) and prints which case, file and
channel or attribute differs.
"""

from __future__ import annotations

import argparse
import enum
import fnmatch
import hashlib
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Iterable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import OpenEXR

REPO = Path(__file__).resolve().parents[1]
HISTORY_FILE = "history.npz"
STATE_PREFIX = "state__"  # svgf_cli/run/history.py _STATE_PREFIX: the Denoiser's arrays in an npz


@dataclass(frozen=True)
class Sequence:
    """A bundled input sequence: folder (under the data root), AOV preset, frame range."""

    folder: str
    aovs: str
    first: int
    last: int

    @property
    def mid(self) -> int:
        """Last frame of the first of two chunks."""
        return (self.first + self.last) // 2


SEQUENCES: dict[str, Sequence] = {
    "seq": Sequence("seq", "svgf", 1, 10),
    # testdata/seq_box holds only references: its inputs are seq's (testdata/README.md),
    # so denoising "seq_box" is the seq case.
    "lag/camera": Sequence("lag/camera", "svgf", 1, 16),
    "lag/glossy": Sequence("lag/glossy", "svgf", 1, 16),
    "lag/light_slide_dim": Sequence("lag/light_slide_dim", "svgf", 1, 16),
    "lag/light_step": Sequence("lag/light_step", "svgf", 1, 16),
    "lag/shadow": Sequence("lag/shadow", "svgf", 1, 16),
    "cycles/roll": Sequence("cycles/roll", "cycles", 1, 10),
    "cycles/metal": Sequence("cycles/metal", "cycles", 1, 10),
    "cycles/offset/roll": Sequence("cycles/offset/roll", "cycles", 1, 3),
}

# Every mode runs on these; the other sequences get FEW_MODES.
CORE_SEQUENCES = ("seq", "lag/glossy", "cycles/roll")
FEW_MODES = ("default", "bidir")

# A step is the arguments of one `svgf denoise` run (after the inputs, output and AOV
# preset), or ("delete", FIRST, LAST) to remove the outputs of frames FIRST..LAST (what a
# killed run had not written yet: the last frames, or a bidirectional run's first ones).
Step = list[str] | tuple[str, int, int]


def _two_chunks(s: Sequence, *extra: str) -> list[Step]:
    return [
        ["--frames", f"{s.first}-{s.mid}", *extra],
        ["--frames", f"{s.mid + 1}-{s.last}", *extra],
    ]


def _chunk_size(s: Sequence) -> str:
    return str(s.mid - s.first + 1)


BIDIR = ("--bidirectional", "--scratch-dir", "{scratch}")

MODES: dict[str, Callable[[Sequence], list[Step]]] = {
    "default": lambda s: [[]],
    "paper": lambda s: [["--preset", "paper"]],
    "falcor": lambda s: [["--preset", "falcor"]],
    "chunks-w2": lambda s: _two_chunks(s, "--warmup", "2"),
    "chunks-all": lambda s: _two_chunks(s, "--warmup", "all"),
    "chunk-size": lambda s: [["--chunk-size", _chunk_size(s), "--warmup", "2"]],
    "dask": lambda s: [["--chunk-size", _chunk_size(s), "--warmup", "2", "--workers", "2"]],
    "bidir": lambda s: [[*BIDIR]],
    "bidir-chunks-all": lambda s: _two_chunks(s, *BIDIR, "--warmup", "all"),
    "bidir-chunks-w2": lambda s: _two_chunks(s, *BIDIR, "--warmup", "2"),
    "bidir-resume": lambda s: [
        [*BIDIR], ("delete", s.first, s.mid), [*BIDIR, "--skip-existing"]
    ],
    "debug-aovs": lambda s: [["--debug-aovs"]],
    "taa": lambda s: [["--taa"]],
    "colour-only-float": lambda s: [["--colour-only", "--float"]],
    "resume": lambda s: [[], ("delete", s.mid, s.last), ["--skip-existing"]],
    "history": lambda s: [
        ["--frames", f"{s.first}-{s.mid}", "--save-history", "{history}"],
        ["--frames", f"{s.mid + 1}-{s.last}", "--load-history", "{history}"],
    ],
}


def all_cases(every_mode: bool = False) -> list[str]:
    """The case names, SEQUENCE:MODE: every mode on CORE_SEQUENCES and FEW_MODES on the
    others, or every mode on every sequence."""
    cases = []
    for name in SEQUENCES:
        modes = MODES if every_mode or name in CORE_SEQUENCES else FEW_MODES
        cases.extend(f"{name}:{mode}" for mode in modes)
    return cases


def select_cases(patterns: Iterable[str], every_mode: bool = False) -> list[str]:
    """Cases matching any pattern: a glob over SEQUENCE:MODE, or a bare sequence or mode."""
    patterns = list(patterns)
    if not patterns:
        return all_cases(every_mode)
    chosen = []
    for case in all_cases(every_mode):
        sequence, mode = case.rsplit(":", 1)
        if any(fnmatch.fnmatchcase(case, p) or p in (sequence, mode) for p in patterns):
            chosen.append(case)
    return chosen


# -- running ---------------------------------------------------------------------------------


def tree_env(tree: Path) -> dict[str, str]:
    """The environment that makes a subprocess import svgf_cli from `tree`."""
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(tree), env.get("PYTHONPATH")) if p)
    env.pop("PYTHONSAFEPATH", None)
    return env


def verify_tree(tree: Path, workdir: Path, dask: bool) -> list[str]:
    """Check (and return, for the log) where a subprocess and a Dask worker import svgf_cli
    from; raise SystemExit when it is not `tree`."""
    script = "import svgf_cli; print(svgf_cli.__file__)"
    if dask:
        script += (
            "\nimport distributed"
            "\nwith distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=True,"
            " dashboard_address=None, silence_logs=40) as c, distributed.Client(c) as cl:"
            "\n    import importlib"
            "\n    for f in cl.run(lambda: importlib.import_module('svgf_cli').__file__)"
            ".values(): print(f)"
        )
    result = subprocess.run(
        [sys.executable, "-c", script], cwd=workdir, env=tree_env(tree),
        capture_output=True, text=True, check=False,
    )
    files = result.stdout.split()
    if result.returncode != 0 or not files:
        raise SystemExit(f"cannot import svgf_cli from {tree}:\n{result.stderr}")
    for file in files:
        if not Path(file).resolve().is_relative_to(tree.resolve()):
            raise SystemExit(f"svgf_cli imported from {file}, not from {tree}")
    return files


def run_case(case: str, tree: Path, data: Path, workdir: Path) -> dict[str, dict[str, str]]:
    """Run one case's steps in `workdir` and hash its outputs."""
    name, mode = case.rsplit(":", 1)
    seq = SEQUENCES[name]
    out_dir = workdir / "out"
    scratch = workdir / "scratch"
    out_dir.mkdir(parents=True)
    scratch.mkdir()
    inputs = data / seq.folder / "in.####.exr"
    fill = {"{scratch}": str(scratch), "{history}": str(out_dir / HISTORY_FILE)}
    for step in MODES[mode](seq):
        if isinstance(step, tuple):
            for frame in range(step[1], step[2] + 1):
                (out_dir / f"den.{frame:04d}.exr").unlink()
            continue
        args = [
            sys.executable, "-m", "svgf_cli", "denoise", str(inputs),
            "-o", str(out_dir / "den.####.exr"), "--preset-aovs", seq.aovs,
            "-q", *(fill.get(a, a) for a in step),
        ]
        result = subprocess.run(
            args, cwd=workdir, env=tree_env(tree), capture_output=True, text=True, check=False
        )
        if result.returncode != 0:
            command = " ".join(args[1:])
            raise RuntimeError(f"exit {result.returncode}: {command}\n{result.stderr[-2000:]}")
    hashes = {}
    for path in sorted(out_dir.iterdir()):
        if path.suffix == ".exr":
            hashes[path.name] = hash_exr(path)
        elif path.suffix == ".npz":
            hashes[path.name] = hash_npz(path)
        else:
            hashes[path.name] = {"file": _digest(path.read_bytes())}
    return hashes


# -- hashing ---------------------------------------------------------------------------------


def _digest(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def _canon(value: Any) -> str:
    """A text form of a header value that depends only on the value (no object ids)."""
    if isinstance(value, np.ndarray):
        return f"ndarray({value.dtype.str},{value.shape},{value.tobytes().hex()})"
    if isinstance(value, np.generic):
        return f"{type(value).__name__}({value.tobytes().hex()})"
    if isinstance(value, list | tuple):
        return "(" + ",".join(_canon(v) for v in value) + ")"
    if isinstance(value, dict):
        return "{" + ",".join(f"{_canon(k)}:{_canon(v)}" for k, v in sorted(value.items())) + "}"
    if isinstance(value, float):
        return value.hex()
    if isinstance(value, enum.Enum):
        return f"{type(value).__name__}.{value.name}={value.value!r}"
    text = repr(value)
    if " at 0x" in text:
        raise ValueError(f"header value without a stable text form: {text}")
    return text


def hash_exr(path: Path) -> dict[str, str]:
    """pixels/header/metadata hashes of every part of an EXR file."""
    hashes = {}
    exr = OpenEXR.File(str(path), separate_channels=True)
    for index, part in enumerate(exr.parts):
        for name, value in part.header.items():
            kind = "metadata" if name.startswith("svgf/") else "header"
            hashes[f"{kind}/{index}/{name}"] = _digest(_canon(value).encode())
        for name, channel in part.channels.items():
            pixels = np.ascontiguousarray(channel.pixels)
            layout = (pixels.dtype.str, pixels.shape, channel.xSampling, channel.ySampling,
                      channel.pLinear)
            hashes[f"pixels/{index}/{name}"] = _digest(repr(layout).encode() + pixels.tobytes())
    return dict(sorted(hashes.items()))


def hash_npz(path: Path) -> dict[str, str]:
    """history/metadata hashes of every array of a --save-history file."""
    hashes = {}
    with np.load(path, allow_pickle=False) as data:
        for name in data.files:
            array = np.ascontiguousarray(data[name])
            kind = "history" if name.startswith(STATE_PREFIX) else "metadata"
            hashes[f"{kind}/{name}"] = _digest(_canon(array).encode())
    return dict(sorted(hashes.items()))


# -- comparing -------------------------------------------------------------------------------


def compare(baseline: dict[str, Any], current: dict[str, Any], pixels_only: bool) -> int:
    """Print every differing case, then a summary; 1 when something differs (metadata-only
    differences too, unless pixels_only)."""
    cases = sorted(k for k in current if not k.startswith("__"))
    identical, different, metadata_only, new = [], [], [], []
    for case in cases:
        if case not in baseline:
            new.append(case)
            continue
        lines = _case_differences(baseline[case], current[case])
        if not lines:
            identical.append(case)
            continue
        kinds = {kind for kind, _ in lines}
        only_metadata = kinds == {"metadata"}
        (metadata_only if only_metadata else different).append(case)
        label = "METADATA" if only_metadata else "DIFFERENT"
        print(f"{label:<9} {case}: {', '.join(sorted(kinds))}")
        for _, line in lines:
            print(f"    {line}")
    missing = [k for k in baseline if not k.startswith("__") and k not in current]
    print(
        f"\n{len(identical) + len(different) + len(metadata_only)} case(s) compared: "
        f"{len(identical)} identical, {len(different)} DIFFERENT (pixels, header, history, "
        f"files or errors), {len(metadata_only)} in svgf/* metadata only"
        + (" (allowed by --pixels-only)" if pixels_only and metadata_only else "")
    )
    if new:
        print(f"{len(new)} case(s) not in the baseline: {', '.join(new)}")
    if missing:
        print(f"{len(missing)} baseline case(s) not run here")
    failed = different or (metadata_only and not pixels_only)
    return 1 if failed else 0


def _case_differences(base: dict[str, Any], cur: dict[str, Any]) -> list[tuple[str, str]]:
    """(kind, line) per file: kind is pixels, header, history, metadata, files or error."""
    if "__error__" in base or "__error__" in cur:
        return [("error", f"baseline: {base.get('__error__', 'ok')} / "
                          f"current: {cur.get('__error__', 'ok')}")]
    lines: list[tuple[str, str]] = []
    for name in sorted(set(base) - set(cur)):
        lines.append(("files", f"{name}: missing (in the baseline only)"))
    for name in sorted(set(cur) - set(base)):
        lines.append(("files", f"{name}: extra (not in the baseline)"))
    for name in sorted(set(base) & set(cur)):
        by_kind: dict[str, list[str]] = {}
        keys = set(base[name]) | set(cur[name])
        for key in sorted(keys):
            b, c = base[name].get(key), cur[name].get(key)
            if b == c:
                continue
            kind, _, rest = key.partition("/")
            mark = "" if b and c else (" (missing)" if b else " (new)")
            by_kind.setdefault(kind, []).append(rest + mark)
        for kind, items in sorted(by_kind.items()):
            lines.append((kind, f"{name}: {kind}: {', '.join(items)}"))
    return lines


# -- main ------------------------------------------------------------------------------------


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tree", type=Path, default=REPO,
                        help="source tree put first on PYTHONPATH (default: this repository)")
    parser.add_argument("--data", type=Path, default=REPO / "testdata",
                        help="the bundled sequences (default: this repository's testdata)")
    parser.add_argument("--out", type=Path, help="write the hashes here (JSON)")
    parser.add_argument("--compare", type=Path, metavar="BASELINE",
                        help="compare with a baseline JSON; exit 1 on any difference")
    parser.add_argument("--current", type=Path, metavar="RESULT",
                        help="with --compare: compare this earlier --out JSON, run nothing")
    parser.add_argument("--pixels-only", action="store_true",
                        help="with --compare: metadata-only differences do not fail")
    parser.add_argument("--only", action="append", default=[], metavar="CASE",
                        help="glob over SEQUENCE:MODE, or a sequence or mode name (repeatable)")
    parser.add_argument("--all-modes", action="store_true",
                        help="every mode on every sequence (default: every mode on "
                        f"{', '.join(CORE_SEQUENCES)}, {' and '.join(FEW_MODES)} on the rest)")
    parser.add_argument("--jobs", type=int, default=1, help="cases run at once (default 1)")
    parser.add_argument("--list", action="store_true", help="list the cases and exit")
    args = parser.parse_args(argv)

    if args.current:
        if not args.compare:
            parser.error("--current needs --compare")
        current = json.loads(args.current.read_text())
        return compare(json.loads(args.compare.read_text()), current, args.pixels_only)
    cases = select_cases(args.only, args.all_modes)
    if args.list:
        print("\n".join(cases))
        return 0
    if not cases:
        parser.error(f"no case matches {args.only}")
    tree = args.tree.resolve()
    started = time.perf_counter()
    results: dict[str, Any] = {}
    seconds: dict[str, float] = {}
    with tempfile.TemporaryDirectory(prefix="svgf-hash-") as tmp:
        root = Path(tmp)
        dask = any(c.endswith(":dask") for c in cases)
        imported = verify_tree(tree, root, dask)
        where = "a subprocess and a Dask worker" if dask else "a subprocess"
        print(f"tree {tree}: svgf_cli imported from {', '.join(sorted(set(imported)))} "
              f"({where})", flush=True)

        def one(item: tuple[int, str]) -> None:
            index, case = item
            workdir = root / f"case{index}"
            workdir.mkdir()
            t0 = time.perf_counter()
            try:
                results[case] = run_case(case, tree, args.data.resolve(), workdir)
                status = f"{len(results[case])} file(s)"
            except (RuntimeError, OSError, ValueError) as exc:
                results[case] = {"__error__": str(exc).splitlines()[0]}
                status = f"ERROR {exc}"
            finally:
                shutil.rmtree(workdir, ignore_errors=True)
            seconds[case] = round(time.perf_counter() - t0, 2)
            print(f"[{len(seconds)}/{len(cases)}] {case}: {status} ({seconds[case]:.1f} s)",
                  flush=True)

        with ThreadPoolExecutor(max_workers=max(1, args.jobs)) as pool:
            list(pool.map(one, enumerate(cases)))
    total = time.perf_counter() - started
    print(f"{len(cases)} case(s) in {total:.1f} s", flush=True)
    output: dict[str, Any] = {case: results[case] for case in cases}
    output["__run__"] = {"tree": str(tree), "seconds": round(total, 1), "case_seconds": seconds}
    if args.out:
        args.out.write_text(json.dumps(output, indent=1, sort_keys=True) + "\n")
    errors = [case for case in cases if "__error__" in results[case]]
    code = 0
    if args.compare:
        code = compare(json.loads(args.compare.read_text()), output, args.pixels_only)
    if errors:
        print(f"{len(errors)} case(s) failed to run: {', '.join(errors)}")
        code = code or 2
    return code


if __name__ == "__main__":
    sys.exit(main())
