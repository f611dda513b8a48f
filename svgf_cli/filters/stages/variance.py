"""Variance estimation: temporal where the history is long, spatial where it is short."""

from __future__ import annotations

from svgf_cli.filters.buffers import combined_role, free_scratch
from svgf_cli.filters.context import FrameContext, Spatial, StageBase
from svgf_cli.filters.variance import estimate_variance


class Variance(StageBase):
    """The luminance variance of each signal's accumulation from its temporal moments
    (Schied et al. 2017, sec. 4.2), estimated spatially (7x7 bilateral) below
    ``variance_history_threshold`` frames of history (with ``spatial_variance_blur_color``
    the colour is blurred there too, Falcor). ``of``: "accumulation" (this pass's own, whose
    a-trous feeds back) or "combination" (a reverse pass's combined histories)."""

    name = "variance"
    reads = ("accumulated", "moments", "history_length", "mode", "depth", "ddx", "ddy",
             "normal")
    writes = ("variance",)

    def __init__(self, of: str = "accumulation") -> None:
        self.of = of
        if of == "combination":
            self.reads = ("combined", "combined_moments", "combined_length", *self.reads[3:])

    def run(self, ctx: FrameContext) -> None:
        work = ctx.work
        if self.of == "combination":
            spatial = Spatial(combined_role(ctx.params.firefly_clamp),
                              work["combined_moments"], work["combined_length"],
                              ctx.iterations, protected=(ctx.history_name,), feeds_back=False)
        else:
            spatial = Spatial("accumulated", work["moments"], work["history_length"],
                              ctx.iterations)
        estimate(ctx, spatial)
        ctx.spatial = spatial


def estimate(ctx: FrameContext, spatial: Spatial) -> None:
    """The variance of ``spatial.source`` into ``variance`` (+ the optional colour blur,
    into a free scratch buffer: ``spatial.entering``)."""
    p, work = ctx.params, ctx.work
    busy = (spatial.source, *spatial.protected)
    variance = work["variance"]
    spatial.entering = spatial.source
    blurred = None
    if p.spatial_variance_blur_color:
        spatial.entering = free_scratch(spatial.protected, *busy)
        blurred = ctx.plane(spatial.entering)
    estimate_variance(
        ctx.plane(spatial.source), spatial.moments, spatial.history_length, ctx.mode,
        ctx.depth, work["ddx"], work["ddy"], ctx.normal,
        history_threshold=float(p.variance_history_threshold),
        radius=p.spatial_variance_radius, sigma_depth=p.sigma_depth,
        sigma_luminance=p.spatial_variance_sigma_luminance, squarings=ctx.setup.squarings,
        sigma_normal=p.sigma_normal, out_variance=variance, out_illumination=blurred,
    )
    spatial.variance = variance
    ctx.lap("variance")
