"""The light layers of a file that `svgf denoise` writes denoised (docs/output.md#light-layers):
its light passes (the lobe passes the signals are built from) and its light groups.

Light groups are found by name next to the colour layer:

* **Cycles** (verified, Blender 4.5): ``<view layer>.Combined_<group>.R/G/B`` next to
  ``<view layer>.Combined`` (View Layer -> Light Groups; no alpha). With every light and the
  world in a group they add up to ``Combined`` (to half rounding).
* **Arnold** (unverified, from the Arnold User Guide's light group AOVs): ``RGBA_<group>``
  next to the beauty ``RGBA`` (or a bare ``R,G,B``).

Other renderers' light AOVs (Karma and RenderMan LPE AOVs) have no fixed names and are not
recognised (they pass through as read).

The groups are checked on read like the light passes (``io.signals.check_sum``): where they
do not add up to the colour (a light in no group), they are written as read, with one
warning for the run.
"""

from __future__ import annotations

import re
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from svgf_cli.frame import Frame, LightLayer, LightLayers, Signal
from svgf_cli.halfconv import gather_float32, zero_nonfinite
from svgf_cli.io.layers import LOBE_LIGHT_DIVIDED, LOBES
from svgf_cli.io.signals import SignalPlan, SumCheck, check_sum
from svgf_cli.io.source import SourceFile

F32 = np.float32
# Layers a light group's name may follow (the colour layer's name, then "_<group>").
_GROUP_BASES = {"Combined": "cycles", "RGBA": "arnold"}
_GROUP_NAME = re.compile(r"(?P<base>.*?)_(?P<group>[^.]+)$")


def colour_layer(colour_channels: Sequence[str] | None) -> str | None:
    """``ViewLayer.Combined`` of ``ViewLayer.Combined.R``; ``""`` for a bare ``R``."""
    if not colour_channels:
        return None
    return colour_channels[0].rpartition(".")[0]


def find_light_groups(channel_names: Iterable[str], colour_channels: Sequence[str] | None
                      ) -> list[tuple[str, tuple[str, str, str]]]:
    """``(group, (R, G, B channel names))`` of every light group next to the colour layer,
    sorted by name. The colour layer ``X`` (``ViewLayer.Combined``, ``RGBA``; a bare ``R,G,B``
    counts as ``RGBA``) has groups ``X_<group>`` with all of R, G and B."""
    layer = colour_layer(colour_channels)
    if layer is None:
        return []
    prefix, _, base = layer.rpartition(".")
    base = base or "RGBA"
    if base not in _GROUP_BASES:
        return []
    names = set(channel_names)
    found: dict[str, tuple[str, str, str]] = {}
    for name in names:
        group_layer, _, channel = name.rpartition(".")
        if channel != "R":
            continue
        head, _, tail = group_layer.rpartition(".")
        if head != prefix:
            continue
        match = _GROUP_NAME.fullmatch(tail)
        if match is None or match["base"] != base:
            continue
        rgb = tuple(f"{group_layer}.{c}" for c in "RGB")
        if all(c in names for c in rgb):
            found[match["group"]] = rgb  # type: ignore[assignment]
    return sorted(found.items())


def _plane(source: SourceFile, names: Sequence[str]) -> np.ndarray | None:
    """The channels ``names`` as a cleaned (3, H, W) float32 plane (non-finite -> 0), or None
    when one has no pixels."""
    planes = []
    for name in names:
        part = source.part_holding(name)
        pixels = None if part is None else part.channels[name].pixels
        if pixels is None:
            return None
        planes.append(pixels)
    plane = gather_float32(planes)
    zero_nonfinite(plane)
    return plane


def _all_zero(source: SourceFile, names: Sequence[str]) -> bool:
    """Whether every value of the channels ``names`` is +0 (bit for bit: a -0 is not)."""
    for name in names:
        part = source.part_holding(name)
        pixels = None if part is None else part.channels[name].pixels
        if pixels is None or pixels.dtype.itemsize not in (2, 4):
            return False
        if np.any(pixels.view(np.uint16 if pixels.dtype.itemsize == 2 else np.uint32)):
            return False
    return True


def _lobe_passes(resolved, preset: str  # noqa: ANN001
                 ) -> Iterator[tuple[str, Sequence[str], Sequence[str] | None]]:
    """Each lobe light pass the layers resolve (three channels): its role
    (``<lobe>_direct``, ``<lobe>_indirect``), its channels, and its colour pass's channels
    when the preset stores the light divided by it."""
    divided = LOBE_LIGHT_DIVIDED.get(preset, True)
    for lobe in LOBES:
        colour_names = resolved[f"{lobe}_color"] if divided else None
        for part in ("direct", "indirect"):
            names = resolved[f"{lobe}_{part}"]
            if names and len(names) == 3:
                yield f"{lobe}_{part}", names, colour_names or None


def pass_layers(source: SourceFile, resolved, plan: SignalPlan | None,  # noqa: ANN001
                preset: str) -> list[LightLayer]:
    """The lobe light passes the file holds (``<lobe>_direct``, ``<lobe>_indirect``), each
    with its colour pass when the preset stores the light divided by it, and the signal of
    ``plan`` built from it. A pass +0 on every pixel (Cycles' ``TransDir`` or ``VolumeInd``,
    often; all four of a shot without glass or volumes) is left out: the output keeps it as
    read, which is what its denoised light would be, and nothing is computed for it."""
    owner: dict[str, str] = {}
    for recipe in (plan.signals if plan is not None else ()):
        for term in recipe.terms:
            for role in term.light:
                owner.setdefault(role, recipe.name)
    found = []
    colours: dict[tuple[str, ...], np.ndarray | None] = {}  # each colour pass read once
    for role, names, colour_names in _lobe_passes(resolved, preset):
        if _all_zero(source, names):
            continue  # written as read: its denoised light is +0 everywhere too
        colour = None
        if colour_names:
            key = tuple(colour_names)
            if key not in colours:
                colours[key] = _plane(source, colour_names)
            colour = colours[key]
        stored = _plane(source, names)
        if stored is not None:
            found.append((role, names, colour_names, colour, stored))
    if not found:
        return []
    # The passes' radiances side by side in one block, in the order of the list: the
    # filter's shares read consecutive passes as one (K, 3, H, W) array without a copy.
    block = np.empty((len(found), *found[0][4].shape), dtype=F32)
    layers = []
    for radiance, (role, names, colour_names, colour, stored) in zip(block, found, strict=True):
        if colour is not None:
            np.multiply(stored, colour, out=radiance)
        else:
            radiance[...] = stored
        layers.append(LightLayer(
            tuple(names), radiance, stored, colour,  # type: ignore[arg-type]
            owner.get(role, ""),
            tuple(colour_names) if colour is not None else None))  # type: ignore[arg-type]
    return layers


def group_layers(source: SourceFile, colour_channels: Sequence[str] | None) -> list[LightLayer]:
    """The light groups next to the colour layer, as read (float32)."""
    names = [n for part in source.parts for n in part.channels]
    layers = []
    for _group, rgb in find_light_groups(names, colour_channels):
        plane = _plane(source, rgb)
        if plane is not None:
            layers.append(LightLayer(rgb, plane, plane))
    return layers


def check_groups(groups: Sequence[LightLayer], frame: Frame) -> SumCheck:
    """The light groups against the frame's colour (its signals plus emission), with the
    light-pass check's tolerance."""
    signals = [Signal(f"g{k}", g.radiance, g.radiance) for k, g in enumerate(groups)]
    return check_sum(signals, None, frame.total_radiance())


def read_light_layers(result, preset: str) -> LightLayers:  # noqa: ANN001
    """The light passes, groups and emission passes of a read (`io.exr.ReadResult`) from its
    decoded file; an emission pass +0 on every pixel is left out (written as read) while
    another one is not."""
    source = getattr(result, "source", None)
    if source is None:
        return LightLayers()
    resolved = result.resolved
    passes = pass_layers(source, resolved, getattr(result, "plan", None), preset)
    groups = group_layers(source, getattr(result, "colour_channels", None))
    found = [names for names in (resolved["emission"], resolved["environment"])
             if names and len(names) == 3]
    # A black emission pass is written as read while another one takes the emission.
    lit = [names for names in found if not _all_zero(source, names)]
    emission = []
    for names in lit or found:
        plane = _plane(source, names)
        if plane is not None:
            emission.append(LightLayer(tuple(names), plane, plane))  # type: ignore[arg-type]
    return LightLayers(passes, groups, emission)


# ------------------------------------------------------------------ additivity of an output

# The sum of a file's light layers against its colour, per pixel and channel:
# |sum - colour| <= ADDITIVITY_RELATIVE max(|sum|, |colour|) + the storage rounding of every
# term (half: 2^-11 of each stored value's magnitude, twice for a light x colour product)
# + ADDITIVITY_ABSOLUTE.
ADDITIVITY_RELATIVE = 1e-3
ADDITIVITY_ABSOLUTE = 1e-6
_ROUNDING = {"half": 2.0 ** -11, "float": 2.0 ** -24}


@dataclass(frozen=True)
class Additivity:
    """One decomposition of a file's colour (``groups``: the light groups; ``passes``: the
    light passes rebuilt as Cycles' formula): how many (pixel, channel) values exceed the
    tolerance and the largest relative error ``|sum - colour| / max(|sum|, |colour|)``
    (values below 1e-4 of the frame's mean colour left out of the maximum)."""

    what: str
    failing: int
    values: int
    worst_relative: float

    @property
    def passed(self) -> bool:
        return self.failing == 0

    def describe(self) -> str:
        state = "passed" if self.passed else "FAILED"
        return (f"{self.what} add up to the colour ({state}): {self.values - self.failing} of "
                f"{self.values} values within {ADDITIVITY_RELATIVE:g} relative + storage "
                f"rounding; largest relative difference {self.worst_relative:.2e}")


def _typed(source: SourceFile, names: Sequence[str]) -> tuple[np.ndarray, float] | None:
    planes, rounding = [], 0.0
    for name in names:
        part = source.part_holding(name)
        channel = None if part is None else part.channels.get(name)
        if channel is None or channel.pixels is None:
            return None
        planes.append(channel.pixels.astype(np.float64))
        rounding = max(rounding, _ROUNDING.get(channel.type_name, 0.0))
    return np.stack(planes), rounding


def _additivity(what: str, colour: tuple[np.ndarray, float],
                terms: list[tuple[np.ndarray, float]]) -> Additivity:
    target, target_rounding = colour
    total = np.zeros_like(target)
    bound = np.abs(target) * target_rounding
    for value, rounding in terms:
        total += value
        bound += np.abs(value) * rounding
    error = np.abs(total - target)
    scale = np.maximum(np.abs(total), np.abs(target))
    tolerance = ADDITIVITY_RELATIVE * scale + bound + ADDITIVITY_ABSOLUTE
    failing = int(np.count_nonzero(error > tolerance))
    shown = scale > 1e-4 * max(float(np.mean(np.abs(target))), 1e-12)
    worst = float(np.max(error[shown] / scale[shown])) if np.any(shown) else 0.0
    return Additivity(what, failing, int(error.size), worst)


def check_additivity(source: SourceFile, resolved, colour_channels: Sequence[str] | None,  # noqa: ANN001
                     preset: str) -> list[Additivity]:
    """The light groups' sum and the light passes' rebuild (``sum over lobes (Dir + Ind) x
    Col + Volume + Emit + Env`` for Cycles; the plain sum for radiance passes) against the
    colour of a file (a denoised output or an input), each when the file has it."""
    if not colour_channels:
        return []
    colour = _typed(source, colour_channels)
    if colour is None:
        return []
    results = []
    names = [n for part in source.parts for n in part.channels]
    groups = [t for _, rgb in find_light_groups(names, colour_channels)
              if (t := _typed(source, rgb)) is not None]
    if groups:
        results.append(_additivity(f"{len(groups)} light groups", colour, groups))
    terms = []
    for _, names_, col_names in _lobe_passes(resolved, preset):
        light = _typed(source, names_)
        if light is None:
            continue
        col = _typed(source, col_names) if col_names else None
        if col is not None:
            light = (light[0] * col[0], light[1] + col[1])
        terms.append(light)
    if terms:
        for role in ("emission", "environment"):
            names_ = resolved[role]
            if names_ and (e := _typed(source, names_)) is not None:
                terms.append(e)
        results.append(_additivity("the light passes", colour, terms))
    return results


def file_additivity(path: str, mapping) -> list[Additivity]:  # noqa: ANN001
    """`check_additivity` of the EXR file ``path`` read with the layer ``mapping``."""
    import OpenEXR

    from svgf_cli.io.layers import resolve_layers, resolve_output_colour
    from svgf_cli.io.source import SourceChannel, SourcePart

    exr = OpenEXR.File(str(path), separate_channels=True)
    parts = []
    for index, part in enumerate(exr.parts):
        source_part = SourcePart(index, part.name(), dict(part.header))
        for name, channel in part.channels.items():
            source_part.channels[name] = SourceChannel(channel.pixels)
        parts.append(source_part)
    source = SourceFile(Path(path), parts)
    names = [n for p in parts for n in p.channels]
    resolved = resolve_layers(mapping, names, str(path), strict=False)
    colour = resolve_output_colour(mapping, names)
    return check_additivity(source, resolved, colour, mapping.preset)
