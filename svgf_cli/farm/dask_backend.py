"""Run planned chunks as Dask distributed tasks (``--workers N`` or ``--scheduler ADDR``).

Each chunk is one task: it reads its warm-up and output frames from shared storage, runs the
same sequential driver as a local run, and writes its frames atomically. A task is
idempotent: outputs that already exist are complete (temp-then-rename), so a retried task
skips them and recomputes only what is missing; recomputed frames are bit-identical anyway.
"""

from __future__ import annotations

import io
import os
import time
from collections.abc import Sequence
from typing import Any

from svgf_cli.errors import UsageError
from svgf_cli.openmp import wait_passively
from svgf_cli.progress import Progress
from svgf_cli.run.chunk import run_sequence
from svgf_cli.run.tasks import FrameTask, RunConfig, RunStats, pending_tasks, trim_tail

# A failed task (a worker died, say) is resubmitted this many times before the job fails.
TASK_RETRIES = 2


def _import_distributed() -> Any:
    try:
        import distributed
    except ImportError:
        raise UsageError(
            "--workers/--scheduler need Dask: pip install 'svgf[farm]' (dask[distributed])"
        ) from None
    return distributed


def set_compute_threads(threads: int | None) -> None:
    """Threads for numba kernels and OpenImageIO in this process (None/0: leave as is)."""
    # Before numba starts its threads (a Dask worker's first task): idle threads sleep.
    wait_passively()
    if not threads:
        return
    import numba

    numba.set_num_threads(max(1, min(threads, numba.config.NUMBA_NUM_THREADS)))
    from svgf_cli.io.exr import set_io_threads

    set_io_threads(threads)


def run_chunk_task(
    tasks: Sequence[FrameTask], config: RunConfig, overwrite: bool
) -> dict[str, Any]:
    """The body of one Dask task; returns a small summary (no pixels travel back)."""
    set_compute_threads(config.threads)
    todo = pending_tasks(tasks, overwrite)
    if not config.params.bidirectional:  # a bidirectional chunk's tail is its reverse warm-up
        todo = trim_tail(todo)
    if not any(t.output is not None for t in todo):
        return {"written": [], "processed": 0, "seconds": 0.0, "pid": os.getpid()}
    quiet = Progress("lines", 0, quiet=True, out=io.StringIO(), err=io.StringIO())
    quiet.show_progress = False
    stats = run_sequence(todo, config, quiet)
    # Warnings from the worker's log go back to the client as text.
    return {
        "written": stats.written,
        "processed": stats.frames_processed,
        "seconds": stats.wall_seconds,
        "read": stats.read_seconds,
        "compute": stats.compute_seconds,
        "write": stats.write_seconds,
        "warnings": quiet.err.getvalue().splitlines(),
        "pid": os.getpid(),
    }


def run_chunks_dask(
    chunk_tasks: Sequence[Sequence[FrameTask]],
    config: RunConfig,
    progress: Progress,
    *,
    workers: int | None = None,
    scheduler: str | None = None,
    overwrite: bool = False,
) -> RunStats:
    """Submit one task per chunk and report frames as chunks finish."""
    distributed = _import_distributed()
    started = time.perf_counter()
    cluster = None
    if scheduler is None:
        # Processes, one thread each: numba kernels and the GIL do not share well, and a
        # worker that dies takes only its own chunk with it (the task is retried).
        cluster = distributed.LocalCluster(
            n_workers=workers or 1,
            threads_per_worker=1,
            processes=True,
            dashboard_address=None,
            silence_logs=40,
        )
        address: Any = cluster
    else:
        address = scheduler
    stats = RunStats()
    try:
        with distributed.Client(address, timeout="30s") as client:
            progress.info(
                f"Dask: {len(chunk_tasks)} chunk task(s) on {client.scheduler.address} "
                f"(cluster ready in {time.perf_counter() - started:.1f} s)"
            )
            started = time.perf_counter()  # the summary times the work, not the start-up
            futures = {
                client.submit(
                    run_chunk_task,
                    list(tasks),
                    config,
                    overwrite,
                    key=f"svgf-chunk-{index}-{tasks[0].frame}-{tasks[-1].frame}",
                    pure=False,
                    retries=TASK_RETRIES,
                ): index
                for index, tasks in enumerate(chunk_tasks)
            }
            try:
                for future in distributed.as_completed(futures):
                    summary = future.result()
                    for line in summary.get("warnings", []):
                        progress.warning(line.removeprefix("WARNING: "))
                    written = summary["written"]
                    per_frame = summary["seconds"] / max(len(written), 1)
                    for frame in written:
                        progress.frame_done(frame, per_frame)
                    stats.frames_processed += summary["processed"]
                    stats.frames_written += len(written)
                    stats.written.extend(written)
                    stats.read_seconds += summary.get("read", 0.0)
                    stats.compute_seconds += summary.get("compute", 0.0)
                    stats.write_seconds += summary.get("write", 0.0)
            except BaseException:
                client.cancel(list(futures))
                raise
    finally:
        if cluster is not None:
            cluster.close()
    stats.wall_seconds = time.perf_counter() - started
    return stats
