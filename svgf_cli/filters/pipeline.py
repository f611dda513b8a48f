"""The filter's pipelines, stage by stage (cf. Falcor's ``SVGFPass::execute``).

Three kinds: ``causal`` (the Denoiser), and the two passes of a bidirectional run:
``forward`` (temporal stages, then the history it resampled is captured for the reverse
pass) and ``reverse`` (temporal stages, the combination with the forward history, spatial
filter and composition on its output frames). An optional feature is an optional stage: it
is in a pipeline when ``stage.enabled(params)``. Adding a heuristic = one module under
``filters.stages`` + one line here. The buffer roles are ``filters.buffers``'.
"""

from __future__ import annotations

from pathlib import Path

from svgf_cli.filters.context import OnOutputFrames, Pipeline, Stage
from svgf_cli.filters.params import PRESETS, SVGFParams
from svgf_cli.filters.stages.accumulate import Accumulate
from svgf_cli.filters.stages.antilag import AntiLag
from svgf_cli.filters.stages.atrous import Atrous
from svgf_cli.filters.stages.capture import Capture
from svgf_cli.filters.stages.combine import Combine
from svgf_cli.filters.stages.combine_albedo import CombineAlbedo
from svgf_cli.filters.stages.demodulate import Demodulate
from svgf_cli.filters.stages.despike import Despike
from svgf_cli.filters.stages.despike_lone import DespikeLone
from svgf_cli.filters.stages.edge_filter import EdgeFilter
from svgf_cli.filters.stages.emission_mean import EmissionMean
from svgf_cli.filters.stages.fill_medium import FillMedium
from svgf_cli.filters.stages.firefly_clamp import FireflyClamp
from svgf_cli.filters.stages.gradients import Gradients
from svgf_cli.filters.stages.history_clamp import HistoryClamp
from svgf_cli.filters.stages.history_gain import HistoryGain
from svgf_cli.filters.stages.medium_coverage import MediumCoverage
from svgf_cli.filters.stages.medium_motion import MediumMotion
from svgf_cli.filters.stages.object_history import AdoptObjectHistory, ObjectHistory
from svgf_cli.filters.stages.pass_history import PassHistory
from svgf_cli.filters.stages.pixel_filter import PixelFilter
from svgf_cli.filters.stages.reflected_albedo import ReflectedAlbedo
from svgf_cli.filters.stages.reflected_lights import MarkReflectedLights
from svgf_cli.filters.stages.release import ReleaseCombination
from svgf_cli.filters.stages.remodulate import Remodulate
from svgf_cli.filters.stages.reproject import Reproject
from svgf_cli.filters.stages.spread_fireflies import SpreadFireflies
from svgf_cli.filters.stages.store_history import StoreHistory
from svgf_cli.filters.stages.taa import TAA
from svgf_cli.filters.stages.temporal_albedo import TemporalAlbedo
from svgf_cli.filters.stages.values import CleanGeometry
from svgf_cli.filters.stages.variance import Variance

KINDS = ("causal", "forward", "reverse")


def temporal(causal: bool = False) -> list[Stage]:
    """Values to the reprojected history, before the blend (every pipeline; ``causal``: the
    causal run's, with the history gain)."""
    return [
        CleanGeometry(),
        FillMedium(),  # medium_fill_radius, frames with volume passes
        MediumCoverage(),  # medium_coverage_radius, frames with medium pixels
        Gradients(),
        ReflectedAlbedo(),  # reflected_albedo
        MarkReflectedLights(),  # glossy_emitter_radiance
        Demodulate(),
        MediumMotion(),  # medium_motion, frames with medium pixels and history
        FireflyClamp(),  # firefly_clamp
        Reproject(),
        ObjectHistory(),  # object_history
        # antilag_gain; causal only: a pass's shortened history is refilled by the other
        *([HistoryGain()] if causal else []),
        HistoryClamp(),  # history_clamp, glossy_history_clamp
        AntiLag(),  # antilag
        AdoptObjectHistory(),  # object_history
        SpreadFireflies(),  # spread_fireflies (glossy signals: glossy_spread_fireflies)
    ]


def composition() -> list[Stage]:
    """The filtered illumination to the output frame."""
    return [Despike(), Remodulate(), DespikeLone()]  # despike: the first and last


def causal() -> list[Stage]:
    return [
        *temporal(causal=True),
        Accumulate(),
        TemporalAlbedo(),  # temporal_albedo
        Variance(),
        Atrous(),  # its feedback_iteration output is the colour history
        StoreHistory(),
        EmissionMean(),  # still_emission_mean
        *composition(),
        TAA(),  # taa
        PixelFilter(),  # pixel_filter
        EdgeFilter(),  # edge_filter
    ]


def forward() -> list[Stage]:
    return [
        *temporal(),
        TemporalAlbedo(),  # temporal_albedo
        Capture(),  # hands back the resampled history
        Accumulate(),
        PassHistory(),
        StoreHistory(),
    ]


def reverse() -> list[Stage]:
    output_frame = OnOutputFrames  # the stages a warm-up frame (no forward history) skips
    return [
        *temporal(),
        Combine(),  # with the forward history, on output frames
        Accumulate(),
        TemporalAlbedo(),  # temporal_albedo
        CombineAlbedo(),  # temporal_albedo, on output frames
        PassHistory(),
        output_frame(Variance("combination")),
        output_frame(Atrous()),
        StoreHistory(),
        EmissionMean(),  # still_emission_mean: backwards in time, warm-up frames too
        *(output_frame(stage) for stage in composition()),
        output_frame(TAA()),  # taa, taa_jittered: backwards in time
        output_frame(PixelFilter()),  # pixel_filter
        output_frame(EdgeFilter()),  # edge_filter
        output_frame(ReleaseCombination()),
    ]


_BUILDERS = {"causal": causal, "forward": forward, "reverse": reverse}


def build(params: SVGFParams, kind: str = "causal") -> Pipeline:
    """The pipeline of ``kind`` for ``params``: the enabled stages in order."""
    if kind not in _BUILDERS:
        raise ValueError(f"unknown pipeline {kind!r} (choose from {', '.join(KINDS)})")
    return Pipeline(kind, [stage for stage in _BUILDERS[kind]() if stage.enabled(params)])


def stage_names(params: SVGFParams, kind: str = "causal") -> list[str]:
    """The names of the stages that run for ``params`` in a pipeline of ``kind``."""
    return list(build(params, kind).names)


def describe(presets: dict[str, SVGFParams] | None = None) -> str:
    """A markdown table per preset and pipeline kind: each stage's name, reads, writes."""
    parts: list[str] = []
    for preset, params in (presets or PRESETS).items():
        for kind in KINDS:
            parts += [f"### `{preset}`, {kind}", "", "| stage | reads | writes |",
                      "| --- | --- | --- |"]
            for stage in build(params, kind).stages:
                reads = ", ".join(stage.reads) or "-"
                writes = ", ".join(stage.writes) or "-"
                parts.append(f"| {stage.name} | {reads} | {writes} |")
            parts.append("")
    return "\n".join(parts)


BEGIN = "<!-- pipeline:begin (generated by svgf_cli.filters.pipeline.update_docs) -->"
END = "<!-- pipeline:end -->"


def update_docs(path: Path, write: bool = True) -> bool:
    """Regenerate the section between :data:`BEGIN` and :data:`END` in ``path``; True when
    it was current. ``python -m svgf_cli.filters.pipeline docs/development.md``."""
    text = path.read_text(encoding="utf-8")
    head, rest = text.split(BEGIN, 1)
    _, tail = rest.split(END, 1)
    new = f"{head}{BEGIN}\n\n{describe()}\n{END}{tail}"
    if write and new != text:
        path.write_text(new, encoding="utf-8")
    return new == text


if __name__ == "__main__":
    import sys

    update_docs(Path(sys.argv[1] if len(sys.argv) > 1 else "docs/development.md"))
