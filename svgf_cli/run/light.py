"""The light layers of each frame read (`--light-layers denoised`, the default): the light
passes and light groups handed to the filter with the frame (`Frame.light_loader`: read once
its colour filter is done); the writer converts the denoised planes to each channel's stored
type (`output.light_channels`).

The light groups are checked on the sequence's first frame read (like the signal set): where
they do not add up to the colour, every frame's groups are written as read, with one warning.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from svgf_cli.progress import Progress
from svgf_cli.run.output import release_light_inputs
from svgf_cli.run.tasks import FrameTask, RunConfig

if TYPE_CHECKING:
    from svgf_cli.frame import LightLayers
    from svgf_cli.io.exr import ReadResult

LIGHT_LAYER_MODES = ("denoised", "as-read")


def light_layers_wanted(config: RunConfig) -> bool:
    """Whether this run writes the light layers denoised (not with --colour-only)."""
    return (getattr(config, "light_layers", "as-read") == "denoised"
            and not getattr(config, "colour_only", False))


class LightLayerReader:
    """Attaches each read frame's light layers (`Frame.light`), deciding on the first frame
    whether its light groups add up to the colour."""

    def __init__(self, config: RunConfig, progress: Progress) -> None:
        self.enabled = light_layers_wanted(config)
        self._preset = config.mapping.preset if self.enabled else ""
        self._progress = progress
        self.groups_ok: bool | None = None

    def attach(self, task: FrameTask, result: ReadResult, release: bool = False) -> None:
        """Give the frame a loader of its light layers (`Frame.light_loader`): a layered
        filter reads them from the decoded file once its colour filter is done, so their
        float32 planes are not held beside its per-frame planes (the file's half-float
        pixels are half their size). With ``release``, the input pixels the layers replace
        are let go once read (`output.release_light_inputs`)."""
        if not self.enabled or getattr(result, "frame", None) is None:
            return

        def load() -> LightLayers | None:
            light = self.read(task, result)
            if release:
                release_light_inputs(result, task, light)
            return light

        result.frame.light_loader = load

    def read(self, task: FrameTask, result: ReadResult) -> LightLayers | None:
        """The frame's light layers (None: it has none to denoise), deciding on the first
        frame read whether its light groups add up to the colour."""
        from svgf_cli.io.lightlayers import check_groups, read_light_layers

        light = read_light_layers(result, self._preset)
        if light.groups and self.groups_ok is None:
            check = check_groups(light.groups, result.frame)
            self.groups_ok = check.passed
            if not check.passed:
                self._progress.warning(
                    f"{task.input}: the light groups do not add up to the colour on "
                    f"{check.share:.2%} of pixels (a light or the world in no group?); "
                    "writing the light groups as read for the whole run"
                )
        if not self.groups_ok:
            light.groups = []
        return light if light.passes or light.groups else None
