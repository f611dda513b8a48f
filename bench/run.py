"""`make bench`: run every benchmark script in its own process and print their reports.

Each bench/bench_*.py exposes main() and prints its own table; a separate process per script
keeps peak-memory readings (ru_maxrss) honest and JIT caches warm per stage. Pass script names
(e.g. `filters e2e`) to run a subset.
"""

from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

from svgf_cli.results import machine_description

BENCH_DIR = Path(__file__).resolve().parent
ORDER = ["filters", "io", "e2e", "trace", "oidn", "production"]


def main(argv: list[str]) -> int:
    wanted = argv or ORDER
    print(f"svgf benchmarks on {machine_description()}", flush=True)
    failed = []
    for name in wanted:
        script = BENCH_DIR / f"bench_{name}.py"
        if not script.exists():
            print(f"\n== {name}: {script.name} not found, skipped", flush=True)
            continue
        print(f"\n== {name} ({script.name})", flush=True)
        start = time.perf_counter()
        rc = subprocess.call([sys.executable, str(script)], cwd=BENCH_DIR.parent)
        print(f"-- {name}: {time.perf_counter() - start:.1f} s wall, exit {rc}", flush=True)
        if rc != 0:
            failed.append(name)
    if failed:
        print(f"\nFAILED: {', '.join(failed)}", flush=True)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
