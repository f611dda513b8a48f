"""`make results`: run every bundled sequence through every method, score them, check the issue
targets and regenerate ``docs/results.md`` with ``docs/results/``.

* :mod:`svgf_cli.results.table`: what runs (sequences and methods, as data);
* :mod:`svgf_cli.results.run`: `svgf denoise` per method, one evaluation pass per sequence;
* :mod:`svgf_cli.results.checks`: the issue targets as pass/fail checks;
* :mod:`svgf_cli.results.page`: the page, plots and contact sheets.

Run: ``python -m svgf_cli.results [--docs DIR] [--only NAME ...] [--methods A,B] [--frames SPEC]``
"""

from svgf_cli.results.machine import machine_description, package_versions

__all__ = ["machine_description", "package_versions"]
