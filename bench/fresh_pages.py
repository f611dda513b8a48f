"""What a fresh frame-sized plane costs on this machine: writing a 1080p RGB float32 plane
(25 MB) into memory just mapped (the lean heap policy maps every block of 1 MiB and up on
its own: `svgf_cli/heap.py`) against writing it into a plane already written once.

On a virtual machine that reports free memory to its host (Linux ``page_reporting``, on the
kernel command line of these machines), a page the process has not touched since the host
took it back costs a fault in the host as well as the guest's zeroing.

Run: ``.venv/bin/python bench/fresh_pages.py [--planes 8] [--rounds 6] [--pause 3]``
(``--pause``: seconds between rounds, long enough for freed memory to be reported).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from svgf_cli.heap import map_large_blocks  # noqa: E402

SHAPE = (3, 1080, 1920)


def page_reporting() -> str:
    try:
        words = Path("/proc/cmdline").read_text().split()
    except OSError:
        return "unknown"
    found = [w for w in words if w.startswith("page_reporting")]
    return ", ".join(found) if found else "not on the kernel command line"


def one_round(planes: int, source: np.ndarray) -> tuple[float, float]:
    """Milliseconds per plane: the first write into fresh planes, then a second write."""
    block = np.empty((planes, *SHAPE), np.float32)
    started = time.perf_counter()
    for plane in block:
        np.copyto(plane, source)
    first = time.perf_counter()
    for plane in block:
        np.copyto(plane, source)
    second = time.perf_counter()
    return 1e3 * (first - started) / planes, 1e3 * (second - first) / planes


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--planes", type=int, default=8)
    parser.add_argument("--rounds", type=int, default=6)
    parser.add_argument("--pause", type=float, default=3.0)
    args = parser.parse_args(argv)
    map_large_blocks()
    source = np.ones(SHAPE, np.float32)
    print(f"page reporting: {page_reporting()}")
    print(f"{args.planes} planes of {np.prod(SHAPE) * 4 / 1e6:.1f} MB per round; "
          f"{args.pause} s between rounds")
    print("round  fresh ms/plane  written ms/plane")
    for index in range(args.rounds):
        fresh, written = one_round(args.planes, source)
        print(f"{index:5d}  {fresh:14.2f}  {written:16.2f}")
        time.sleep(args.pause if index % 2 == 0 else 0.0)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
