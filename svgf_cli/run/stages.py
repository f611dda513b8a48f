"""The names of the filter stages a run applies: logged at the start of each chunk
(`describe_stages`, ``svgf denoise -v``) and written to each output as ``svgf/stages``
(`run_stages`).
"""

from __future__ import annotations

from typing import Literal

from svgf_cli.filters.params import SVGFParams

PassKind = Literal["causal", "forward", "reverse"]


def stage_names(params: SVGFParams, kind: PassKind) -> list[str]:
    """The stages of the pipeline of one pass (``kind``), in order
    (``filters.pipeline.stage_names``)."""
    from svgf_cli.filters.pipeline import stage_names as pipeline_stages

    return pipeline_stages(params, kind)


def describe_stages(params: SVGFParams) -> list[str]:
    """The start-up lines naming the stages of each pass of a run."""
    kinds: tuple[PassKind, ...] = (
        ("forward", "reverse") if params.bidirectional else ("causal",)
    )
    lines = []
    for kind in kinds:
        stages = stage_names(params, kind)
        if stages:
            lines.append(f"{kind} stages: {', '.join(stages)}")
    return lines


def run_stages(params: SVGFParams) -> list[str]:
    """The stages of a run: a causal run's, or both passes' of a bidirectional run (each
    name prefixed by its pass: ``forward:<stage>``, then ``reverse:<stage>``)."""
    if not params.bidirectional:
        return stage_names(params, "causal")
    return [f"forward:{s}" for s in stage_names(params, "forward")] + [
        f"reverse:{s}" for s in stage_names(params, "reverse")
    ]
