"""Shared pytest fixtures. Synthetic frame builders live in ``tests/synthetic.py``
(import them as ``from synthetic import make_frame``; pytest puts ``tests/`` on sys.path).

Also the test order of a parallel run (``make test``: ``pytest -n 2 --dist worksteal``), see
``pytest_collection_modifyitems``.
"""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))

from svgf_cli.filters.params import SVGFParams, resolve_params  # noqa: E402
from svgf_cli.openmp import wait_passively  # noqa: E402

# The OpenMP wait policy `svgf` sets in main() (svgf_cli.openmp), here for the whole test
# process: OpenMP reads it once, when the first parallel kernel loads it, and many tests call
# kernels directly, not through main(). Spinning idle threads otherwise burn the cores that the
# other pytest-xdist worker (and the suite's subprocesses) need; outputs do not depend on it.
wait_passively()

# On a clean clone most of the suite's time is numba compiling the kernels (cache=True writes
# them next to the sources, where every later process loads them). The first tests (the
# robustness suite) run the whole pipeline, so they compile its kernels one after the other.
# Under `--dist worksteal` the second worker starts at the middle of the collection: these
# files lead its half, so that it compiles other kernels meanwhile, with the signatures the
# pipeline calls them with (reproject: test_filters_resample; despike, remodulate, ...:
# test_reference_stages; the path tracer's: test_trace_*; anti-lag's contiguous variants, which
# the robustness suite's overscan case needs next: test_filters_antilag), and each worker loads
# from the cache what the other compiled. Only the order changes: every test still runs, on
# its own inputs; a name here that no longer matches costs time, never a result.
SECOND_WORKER_LEADS = (
    "test_filters_resample.py",
    "test_reference_stages.py",
    "test_trace_*.py",
    "test_filters_antilag.py",
)


@pytest.hookimpl(optionalhook=True)
def pytest_configure_node(node) -> None:  # noqa: ANN001 - xdist's WorkerController
    """xdist's controller, per worker: pass the ``--dist`` mode on (a worker's own is "no")."""
    node.workerinput["svgf_dist"] = node.config.getoption("dist")


def _worksteal_workers(config: pytest.Config) -> int:
    """How many xdist workers share the run with ``--dist worksteal`` (0: not such a run)."""
    workerinput = getattr(config, "workerinput", None)
    if workerinput is None or workerinput.get("svgf_dist") != "worksteal":
        return 0
    return int(workerinput.get("workercount", 0))


@pytest.hookimpl(trylast=True)  # after -k / -m deselection: the list xdist will split
def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Under ``--dist worksteal`` with two or more workers, move the files of
    ``SECOND_WORKER_LEADS`` (in that order) to where the second worker's share starts.

    worksteal hands each idle worker an equal contiguous share of the collection (the first
    ``len // workers`` tests, then an equal share of the rest) and balances by stealing
    later; every worker collects, and so reorders, alike. Anywhere else (a plain run, other
    ``--dist`` modes) the order is left as collected.
    """
    workers = _worksteal_workers(config)
    if workers < 2:
        return
    leads: list[pytest.Item] = []
    taken: set[int] = set()
    for pattern in SECOND_WORKER_LEADS:
        for item in items:
            if id(item) not in taken and item.path.match(pattern):
                leads.append(item)
                taken.add(id(item))
    start = len(items) // workers  # where the second worker's share starts
    if not leads or len(leads) > len(items) - start:
        return
    rest = [item for item in items if id(item) not in taken]
    items[:] = [*rest[:start], *leads, *rest[start:]]


@pytest.fixture
def paper_params() -> SVGFParams:
    """The paper preset (the default parameters)."""
    return resolve_params("paper")
