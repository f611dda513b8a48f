"""The file driver shared by local runs, local chunks and Dask tasks.

Given the ordered frames of one chunk (`tasks.FrameTask`: frame number, input path, output
path or None for a history-only frame), `chunk.run_sequence` runs the filter frame by frame:
`causal` for a causal run, `bidirectional` (two passes, the forward state spilled to a
scratch folder) for ``--bidirectional``. Its parts, one module each:

* `tasks`: the frames of a chunk, the run's options (`RunConfig`), what a run did
  (`RunStats`), resume helpers (`pending_tasks`, `trim_tail`) and the warm-up count;
* `stop`: SIGINT/SIGTERM as a stop flag (`stop_on_signals`, `Interrupted`) and their
  blocking on the I/O threads;
* `history`: ``--save-history`` / ``--load-history`` files;
* `output`: what is written for a denoised frame (`build_output`, `output_attributes`);
* `workers`: the reader thread (`ReadAhead`) and the writer thread (`WriteBehind`);
* `scratch`: a bidirectional run's spill writer and state reader threads;
* `filter`: the filter of one pass and the checks each frame passes (`FrameFilter`);
* `stages`: the names of the filter stages a run applies (logged, and in ``svgf/stages``);
* `causal`, `bidirectional`: the drivers; `chunk`: the choice between them.

Imports go one way only (no cycle, lazy imports included: tests/test_run_imports.py); a
module imports only modules of later groups in ``chunk`` -> ``causal``, ``bidirectional``
-> ``filter``, ``workers``, ``scratch`` -> ``output``, ``history``, ``stop`` -> ``stages``,
``tasks``. This package's ``__init__`` imports nothing.

Memory holds about three frames whatever the sequence length. SIGINT/SIGTERM finish the frame
in flight and then stop (exit 130/143); the I/O threads never receive them.
"""
