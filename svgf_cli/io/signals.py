"""Signal sets: which noisy signals a file's layers are filtered as, and the light-pass check.

A *signal set* names how a frame's noisy light is split into signals, each filtered on its
own (its own history, variance and demodulation colour) and summed after filtering, with the
noise-free emission added back once:

* ``lobes``: one signal per light lobe the file has (``diffuse``, ``glossy``,
  ``transmission``, ``volume``), each demodulated by its own colour pass;
* ``lobes-split``: as ``lobes``, but the diffuse lobe's direct and indirect light are two
  signals (``diffuse_direct``, ``diffuse_indirect``);
* ``direct-indirect``: the paper's pair, from the file's own direct/indirect layers or summed
  over the lobes, demodulated by one albedo;
* ``combined``: the colour minus the emission, demodulated by the albedo.

`plan_signals` decides from the header which sets a file offers (in the preset's ``auto``
order) and how the chosen one is composed (a `SignalPlan`); `compose_signals` builds the
signals from cleaned role planes; `check_sum` tests that the light passes add up to the
file's colour (they do not under light groups, holdouts, shadow catchers or missing volume
passes), in which case the reader falls back to ``combined``.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from svgf_cli.errors import InputError
from svgf_cli.frame import Signal, TemporalGradient
from svgf_cli.io.layers import (
    EMISSION_IN_DIRECT,
    LOBE_LIGHT_DIVIDED,
    LOBES,
    SIGNAL_SETS,
    LayerMapping,
    ResolvedLayers,
    match_channels,
)

# Which set `--signals auto` takes: the first one the file offers, per AOV preset. Chosen by
# the measurements in docs/signals.md (bench/signal_sets.py, default preset): lobes-split
# keeps the glossy lobe a signal of its own, so the filter's glossy rules apply to it; on
# Cycles' metal that is 0.35 relMSE against 12.5 for direct-indirect, on the tracer's
# glossy sequence 0.011 against 0.015, on Cycles' roll within 1 % of direct-indirect. The
# unverified presets follow the same order.
_ORDER = ("lobes-split", "direct-indirect", "lobes", "combined")
AUTO_ORDER: dict[str, tuple[str, ...]] = {
    "svgf": _ORDER, "cycles": _ORDER, "arnold": _ORDER, "karma": _ORDER,
}

# The demodulation colour of `direct-indirect` when it is summed over the lobes: the albedo
# role, or the lobes' colour passes summed and capped at 1. For Cycles the colour passes: its
# Denoising Albedo follows reflections (no reflectance on mirrors, the reflected object's
# colour on glossy floors), which measured 0.19 against 0.13 relMSE on roll and 10 % against
# 1 % hot pixels on metal (docs/signals.md).
DIRECT_INDIRECT_ALBEDO: dict[str, str] = {
    "svgf": "albedo",
    "cycles": "lobe-colours",
    "arnold": "albedo",
    "karma": "albedo",
}

# The light-pass check (sum of the signals + emission against the file's colour), per pixel
# and channel: |sum - colour| <= CHECK_RELATIVE * max(sum, colour) + floor, with floor =
# CHECK_FLOOR * the frame's mean colour + CHECK_ABSOLUTE. Half-stored passes differ from the
# half-stored colour by at most 1.3e-3 relative on the Cycles fixtures, so 1e-2 leaves a
# margin of 8 while a missing lobe is off by its whole share. The floor keeps black pixels
# (where a relative test means nothing) from failing on half rounding, at any exposure.
CHECK_RELATIVE = 1e-2
CHECK_FLOOR = 1e-3
CHECK_ABSOLUTE = 1e-6
# More failing pixels than this share and the light passes do not describe the image.
CHECK_SHARE = 1e-3

# Signals whose A-SVGF gradient samples (`svgf trace --gradient-samples`) are summed to give
# the combined colour's: luminance is linear, so the samples of direct + indirect are those
# of their sum.
_COMBINED_GRADIENT = ("direct", "indirect")


@dataclass(frozen=True)
class Term:
    """One part of a signal's radiance: the sum of the ``light`` roles, multiplied by the
    ``colour`` role when the renderer stored that light divided by its colour."""

    light: tuple[str, ...]
    colour: str | None = None


@dataclass(frozen=True)
class SignalRecipe:
    """How one signal is built: radiance = sum of ``terms`` (minus the emission when it is
    part of them); demodulated by ``albedo`` (one role as is, several summed, capped at 1
    as a reflectance when ``albedo_cap``; none: white, i.e. filtered as radiance);
    ``gradient`` names the gradient samples summed into its `TemporalGradient` (empty:
    none); ``guide_albedo``: ``albedo`` is the G-buffer albedo AOV, not this light's own
    reflectance (``Signal.guide_albedo``); ``mixed``: direct and indirect light together
    (``Signal.mixed``)."""

    name: str
    terms: tuple[Term, ...]
    albedo: tuple[str, ...]
    minus_emission: bool = False
    gradient: tuple[str, ...] = ()
    glossy: bool = False
    albedo_cap: bool = True
    guide_albedo: bool = False
    mixed: bool = False


# Lobes whose light follows reflections or refractions rather than the surface
# (``Signal.glossy``: the filter clamps their history to the current neighbourhood).
GLOSSY_LOBES = frozenset({"glossy", "transmission"})
# Both present: one signal, "specular". They take the same rules, most pixels hold at most
# one of them (transmission is black wherever there is no glass), and every signal costs a
# full temporal and spatial filter (at 1080p about 0.1 s; docs/signals.md).
SPECULAR = "specular"


@dataclass(frozen=True)
class SignalPlan:
    """The signal set a file is read as: its signals, its emission roles (summed, added back
    after filtering), whether the light-pass check applies (sets built from lobe passes),
    the sets the file offers (in the preset's auto order) and the gradient-sample channels
    (``mask`` and, per sample name, ``(prev, curr)``)."""

    set: str
    signals: tuple[SignalRecipe, ...]
    emission: tuple[str, ...]
    checked: bool
    offered: tuple[str, ...]
    gradient_mask: str | None = None
    gradient_channels: tuple[tuple[str, tuple[str, str]], ...] = ()

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(s.name for s in self.signals)

    def roles(self) -> tuple[str, ...]:
        """Every role the plan reads (the colour too when the check needs it)."""
        roles: list[str] = []
        for recipe in self.signals:
            for term in recipe.terms:
                roles.extend(term.light)
                if term.colour:
                    roles.append(term.colour)
            roles.extend(recipe.albedo)
        roles.extend(self.emission)
        if self.checked:
            roles.append("color")
        return tuple(dict.fromkeys(roles))

    def light_roles(self) -> tuple[str, ...]:
        """The roles holding the signals' light (not colours, emission or the checked colour)."""
        return tuple(dict.fromkeys(r for s in self.signals for t in s.terms for r in t.light))

    def gradient_names(self) -> tuple[str, ...]:
        return tuple(name for name, _ in self.gradient_channels)

    def describe(self, resolved: ResolvedLayers, requested: str = "auto") -> list[str]:
        """Lines for the start-up layer table and `svgf inspect`."""
        asked = "auto" if requested == "auto" else f"asked for {requested}"
        lines = [f"  signals: {self.set} ({asked}; offered in auto order: "
                 f"{', '.join(self.offered) or 'none'})"]
        channels = dict(self.gradient_channels)
        for recipe in self.signals:
            parts = [_term_text(term, resolved) for term in recipe.terms]
            text = " + ".join(parts)
            if recipe.minus_emission and self.emission:
                text += " - emission"
            line = f"    {recipe.name} = {text}, demodulated by {_albedo_text(recipe, resolved)}"
            if recipe.gradient:
                shown = " + ".join(_layer(channels[name]) for name in recipe.gradient)
                line += f"; gradient samples {shown}"
            if recipe.glossy:
                line += "; glossy (follows reflections)"
            lines.append(line)
        emission = " + ".join(_layer(resolved[r]) for r in self.emission) or "none"
        lines.append(f"    emission = {emission} (not filtered, added back)")
        if self.checked:
            lines.append(
                f"    checked on read: signals + emission = {_layer(resolved['color'])} within "
                f"{CHECK_RELATIVE:g} relative, else combined (more than {CHECK_SHARE:.1%} "
                "of pixels off)"
            )
        return lines


def _layer(channels: Sequence[str] | None) -> str:
    """``(ViewLayer.DiffDir.R, ...G, ...B)`` -> ``ViewLayer.DiffDir``; ``R,G,B`` as is."""
    if not channels:
        return "-"
    layers = {name.rpartition(".")[0] for name in channels}
    if len(layers) == 1 and "" not in layers:
        return layers.pop()
    return ",".join(channels)


def _term_text(term: Term, resolved: ResolvedLayers) -> str:
    light = " + ".join(_layer(resolved[r]) for r in term.light)
    if term.colour is None:
        return light
    light = f"({light})" if len(term.light) > 1 else light
    return f"{light} x {_layer(resolved[term.colour])}"


def _albedo_text(recipe: SignalRecipe, resolved: ResolvedLayers) -> str:
    if not recipe.albedo:
        return "white (filtered as radiance)"
    names = [_layer(resolved[r]) for r in recipe.albedo]
    if len(names) == 1:
        return names[0]
    total = " + ".join(names)
    return f"min({total}, 1)" if recipe.albedo_cap else total


# ------------------------------------------------------------------------------ planning


@dataclass(frozen=True)
class _Lobes:
    """The lobes a file has (both light passes and, where needed, the colour) and what keeps
    the others out."""

    present: tuple[str, ...]
    problems: tuple[str, ...]


def _lobes(mapping: LayerMapping, resolved: ResolvedLayers) -> _Lobes:
    divided = LOBE_LIGHT_DIVIDED.get(mapping.preset, True)
    present: list[str] = []
    problems: list[str] = []
    for lobe in LOBES:
        direct, indirect = resolved[f"{lobe}_direct"], resolved[f"{lobe}_indirect"]
        colour = resolved[f"{lobe}_color"]
        has_colour_role = bool(mapping.candidates.get(f"{lobe}_color"))
        if direct is None and indirect is None:
            continue
        if direct is None or indirect is None:
            problems.append(f"{lobe} has only its {'direct' if direct else 'indirect'} light")
        elif divided and has_colour_role and colour is None:
            looked = " or ".join(",".join(c) for c in mapping.candidates[f"{lobe}_color"])
            problems.append(f"{lobe} light without its colour pass (looked for {looked})")
        else:
            present.append(lobe)
    return _Lobes(tuple(present), tuple(problems))


def _supports(name: str, resolved: ResolvedLayers, lobes: _Lobes) -> bool:
    has_colour = resolved["color"] is not None
    lobe_based = bool(lobes.present) and not lobes.problems and has_colour
    if name == "lobes":
        return lobe_based
    if name == "lobes-split":
        return lobe_based and "diffuse" in lobes.present
    if name == "direct-indirect":
        return resolved.split or lobe_based
    return has_colour  # combined


def _why_not(name: str, mapping: LayerMapping, resolved: ResolvedLayers, lobes: _Lobes) -> str:
    """Why the file does not offer set ``name`` (for the error of an explicit --signals)."""
    if lobes.problems:
        return "; ".join(lobes.problems)
    if name != "combined" and not lobes.present:
        looked = ", ".join(
            " or ".join(",".join(c) for c in mapping.candidates.get(f"{lobe}_{part}", ()))
            for lobe in ("diffuse", "glossy")
            for part in ("direct", "indirect")
        )
        extra = " or direct and indirect layers" if name == "direct-indirect" else ""
        return f"no light passes (looked for {looked}){extra}"
    if name == "lobes-split" and "diffuse" not in lobes.present:
        return "no diffuse light passes"
    return "no colour layer (the light passes are checked against it)"


def _gradient_channels(
    channel_names: Sequence[str],
) -> tuple[str | None, dict[str, tuple[str, str]]]:
    """The gradient layer's mask channel and, per sample name, its (prev, curr) channels."""
    present = set(channel_names)
    mask = match_channels(("gradient.mask",), channel_names)
    if mask is None:
        return None, {}
    samples: dict[str, tuple[str, str]] = {}
    prefix = mask[0][: -len("gradient.mask")]
    for name in channel_names:
        if not name.startswith(prefix + "gradient.") or not name.endswith(".prev"):
            continue
        sample = name[len(prefix) + len("gradient.") : -len(".prev")]
        curr = f"{prefix}gradient.{sample}.curr"
        if sample and "." not in sample and curr in present:
            samples[sample] = (name, curr)
    return mask[0], samples


def _gradient_for(name: str, samples: dict[str, tuple[str, str]]) -> tuple[str, ...]:
    """The samples that measure signal ``name``'s change: its own (by name), or for the
    combined colour the sum of direct and indirect. The diffuse signals of `lobes-split` get
    none from ``diffuse``: those samples measure direct + indirect, which is neither half (a
    moving shadow changes the direct light alone; the sum's relative change understates it
    there and invents one for the indirect light)."""
    if name in samples:
        return (name,)
    if name == "color" and all(n in samples for n in _COMBINED_GRADIENT):
        return _COMBINED_GRADIENT
    return ()


def _recipes(
    name: str, mapping: LayerMapping, resolved: ResolvedLayers, lobes: _Lobes
) -> tuple[tuple[SignalRecipe, ...], bool]:
    """The signals of set ``name`` and whether the set is built from lobe passes."""
    divided = LOBE_LIGHT_DIVIDED.get(mapping.preset, True)

    def colour(lobe: str) -> str | None:
        role = f"{lobe}_color"
        return role if resolved[role] is not None else None

    def times(lobe: str) -> str | None:  # the colour the stored light is multiplied by
        return colour(lobe) if divided else None

    def lobe_signal(lobe: str, parts: tuple[str, ...] = ("direct", "indirect"),
                    signal: str | None = None) -> SignalRecipe:
        own = colour(lobe)
        light = tuple(f"{lobe}_{part}" for part in parts)
        return SignalRecipe(signal or lobe, (Term(light, times(lobe)),), (own,) if own else (),
                            glossy=lobe in GLOSSY_LOBES, mixed=len(parts) > 1)

    def per_lobe(lobe_names: Sequence[str]) -> list[SignalRecipe]:
        """One signal per lobe, the glossy lobes merged into one when both are present."""
        specular = [lobe for lobe in lobe_names if lobe in GLOSSY_LOBES]
        signals: list[SignalRecipe] = []
        for lobe in lobe_names:
            if len(specular) < 2 or lobe not in GLOSSY_LOBES:
                signals.append(lobe_signal(lobe))
            elif lobe == specular[0]:
                # Demodulated by the sum of the colours, uncapped: where one lobe is black
                # the signal is exactly the other lobe's (a metal's colour above 1 stays
                # radiance, as in its own signal).
                parts = [lobe_signal(one) for one in specular]
                signals.append(SignalRecipe(
                    SPECULAR, tuple(t for p in parts for t in p.terms),
                    tuple(a for p in parts for a in p.albedo), glossy=True, albedo_cap=False,
                    mixed=True))
        return signals

    if name == "lobes":
        return tuple(per_lobe(lobes.present)), True
    if name == "lobes-split":
        signals = [lobe_signal("diffuse", ("direct",), "diffuse_direct"),
                   lobe_signal("diffuse", ("indirect",), "diffuse_indirect")]
        signals += per_lobe([lobe for lobe in lobes.present if lobe != "diffuse"])
        return tuple(signals), True
    if name == "direct-indirect":
        if resolved.split:
            inside = EMISSION_IN_DIRECT.get(mapping.preset, True)
            return (
                SignalRecipe("direct", (Term(("direct",)),), ("albedo",), minus_emission=inside,
                             guide_albedo=True),
                SignalRecipe("indirect", (Term(("indirect",)),), ("albedo",), guide_albedo=True),
            ), False
        if DIRECT_INDIRECT_ALBEDO.get(mapping.preset) == "lobe-colours":
            albedo = tuple(c for lobe in lobes.present if (c := colour(lobe)) is not None)
        else:
            albedo = ("albedo",)
        # Summed lobes over the G-buffer albedo: glossy light over a dark diffuse base, as
        # in the combined colour (Signal.guide_albedo: its floor and firefly colour test).
        return tuple(
            SignalRecipe(part, tuple(Term((f"{lobe}_{part}",), times(lobe))
                                     for lobe in lobes.present), albedo,
                         guide_albedo=albedo == ("albedo",))
            for part in ("direct", "indirect")
        ), True
    return (SignalRecipe("color", (Term(("color",)),), ("albedo",), minus_emission=True,
                         guide_albedo=True, mixed=True),), False


def plan_signals(
    mapping: LayerMapping,
    resolved: ResolvedLayers,
    channel_names: Sequence[str],
    path: str | None = None,
    *,
    requested: str | None = None,
    strict: bool = True,
) -> SignalPlan | None:
    """The signal set ``mapping.signals`` (or ``requested``) reads this file as.

    ``auto`` takes the first set of the preset's `AUTO_ORDER` the file offers. A set the
    file cannot offer raises InputError naming what is missing (with ``strict``; else None,
    with a note in ``resolved.notes``). Header only: the light-pass check needs the pixels
    (`check_sum`, run by the reader).
    """
    lobes = _lobes(mapping, resolved)
    order = AUTO_ORDER.get(mapping.preset, SIGNAL_SETS)
    offered = tuple(s for s in order if _supports(s, resolved, lobes))
    for problem in lobes.problems:
        note = f"lobe sets unavailable: {problem}"
        if note not in resolved.notes:
            resolved.notes.append(note)
    wanted = requested or mapping.signals
    if wanted == "auto":
        if not offered:
            return None
        chosen = offered[0]
    elif wanted in offered:
        chosen = wanted
    else:
        reason = _why_not(wanted, mapping, resolved, lobes)
        which = (f"signal set {wanted} (chosen on the first frame)" if mapping.signals_fixed
                 else f"--signals {wanted}")
        if strict:
            raise InputError(f"{which} is not possible: {reason}", path)
        resolved.notes.append(f"{which} is not possible: {reason}")
        return None
    recipes, checked = _recipes(chosen, mapping, resolved, lobes)
    mask, samples = _gradient_channels(channel_names)
    if mask is not None:
        recipes = tuple(
            dataclasses.replace(r, gradient=_gradient_for(r.name, samples)) for r in recipes
        )
    used = {name for r in recipes for name in r.gradient}
    emission = tuple(role for role in ("emission", "environment") if resolved[role] is not None)
    return SignalPlan(
        set=chosen,
        signals=recipes,
        emission=emission,
        checked=checked,
        offered=offered,
        gradient_mask=mask if used else None,
        gradient_channels=tuple((n, samples[n]) for n in sorted(used)),
    )


# --------------------------------------------------------------------------- composition


def _sum(planes: Sequence[np.ndarray]) -> np.ndarray:
    """The planes' float32 sum (the plane itself when there is one: no copy)."""
    if len(planes) == 1:
        return planes[0]
    total = np.add(planes[0], planes[1], dtype=np.float32)
    for plane in planes[2:]:
        total += plane
    return total


class _Roles:
    """Role planes for one composition: fetched on first use, let go after the last one, so a
    frame's light passes are not all held at once."""

    def __init__(self, plan: SignalPlan, fetch: Callable[[str], np.ndarray],
                 release: Callable[[str], None]) -> None:
        uses: dict[str, int] = {}
        for recipe in plan.signals:
            for term in recipe.terms:
                for role in (*term.light, *((term.colour,) if term.colour else ())):
                    uses[role] = uses.get(role, 0) + 1
            for role in recipe.albedo:
                uses[role] = uses.get(role, 0) + 1
        for role in plan.emission:
            uses[role] = uses.get(role, 0) + 1
        self._uses = uses
        self._fetch = fetch
        self._release = release

    def __call__(self, role: str) -> np.ndarray:
        plane = self._fetch(role)
        self._uses[role] -= 1
        if self._uses[role] == 0:
            self._release(role)
        return plane


def _term(term: Term, role: _Roles) -> tuple[np.ndarray, bool]:
    """A term's radiance and whether it is a fresh array (safe to modify in place)."""
    lights = [role(r) for r in term.light]
    light, fresh = _sum(lights), len(lights) > 1
    if term.colour is not None:
        colour = role(term.colour)
        if fresh:
            np.multiply(light, colour, out=light)
        else:
            light, fresh = np.multiply(light, colour, dtype=np.float32), True
    return light, fresh


def compose_signals(
    plan: SignalPlan,
    fetch: Callable[[str], np.ndarray],
    channel: Callable[[str], np.ndarray],
    release: Callable[[str], None] = lambda _role: None,
) -> tuple[list[Signal], np.ndarray | None]:
    """The plan's signals and emission from ``fetch(role)`` (a cleaned (3, H, W) float32
    plane) and ``channel(name)`` (an (H, W) float32 channel, for gradient samples).
    ``release(role)`` is called after a role's last use.

    Radiance from lobe passes is ``(Dir + Ind) x Col`` in float32, the renderer's own
    identity, so the signals add up to its colour to within the storage rounding. Returned
    arrays may be the role planes themselves: callers must not modify them.
    """
    role = _Roles(plan, fetch, release)
    emission = _sum([role(r) for r in plan.emission]) if plan.emission else None
    white: np.ndarray | None = None
    signals: list[Signal] = []
    for recipe in plan.signals:
        radiance, fresh = _term(recipe.terms[0], role)
        for term in recipe.terms[1:]:
            part, _ = _term(term, role)
            if fresh:
                radiance += part
            else:
                radiance, fresh = np.add(radiance, part, dtype=np.float32), True
        if recipe.minus_emission and emission is not None:
            if fresh:
                radiance -= emission
            else:
                radiance = np.subtract(radiance, emission, dtype=np.float32)
        if not recipe.albedo:
            if white is None:
                white = np.ones_like(radiance)
            albedo = white
        elif len(recipe.albedo) == 1:
            albedo = role(recipe.albedo[0])
        else:
            albedo = _sum([role(r) for r in recipe.albedo])
            if recipe.albedo_cap:
                np.minimum(albedo, np.float32(1.0), out=albedo)
        signals.append(Signal(recipe.name, np.ascontiguousarray(radiance), albedo,
                              _gradient(plan, recipe, channel), glossy=recipe.glossy,
                              guide_albedo=recipe.guide_albedo, mixed=recipe.mixed))
    return signals, emission


def _gradient(
    plan: SignalPlan, recipe: SignalRecipe, channel: Callable[[str], np.ndarray]
) -> TemporalGradient | None:
    if not recipe.gradient or plan.gradient_mask is None:
        return None
    channels = dict(plan.gradient_channels)
    previous = _sum([channel(channels[n][0]) for n in recipe.gradient])
    current = _sum([channel(channels[n][1]) for n in recipe.gradient])
    return TemporalGradient(channel(plan.gradient_mask), previous, current)


# ------------------------------------------------------------------------------ the check


@dataclass(frozen=True)
class SumCheck:
    """How well the signals plus the emission reproduce the file's colour: pixels off by
    more than the tolerance (any channel), of all pixels, and the worst error in units of
    the tolerance."""

    failing: int
    pixels: int
    worst: float

    @property
    def share(self) -> float:
        return self.failing / max(self.pixels, 1)

    @property
    def passed(self) -> bool:
        return self.share <= CHECK_SHARE

    def describe(self) -> str:
        return (f"signals + emission match the colour on {self.pixels - self.failing} of "
                f"{self.pixels} pixels ({self.share:.2%} off; worst error "
                f"{self.worst:.2g}x the tolerance)")


def check_sum(signals: Sequence[Signal], emission: np.ndarray | None,
              colour: np.ndarray) -> SumCheck:
    """Per pixel and channel: ``|sum - colour| <= CHECK_RELATIVE max(sum, colour) + floor``,
    ``floor = CHECK_FLOOR mean(colour) + CHECK_ABSOLUTE`` (see the constants). One channel
    at a time: two (H, W) planes of scratch memory."""
    floor = np.float32(CHECK_FLOOR * float(np.mean(colour, dtype=np.float64)) + CHECK_ABSOLUTE)
    failing = np.zeros(colour.shape[1:], dtype=bool)
    worst = 0.0
    for c in range(colour.shape[0]):
        total = np.zeros_like(colour[c]) if emission is None else emission[c].copy()
        for signal in signals:
            total += signal.radiance[c]
        error = np.subtract(total, colour[c], dtype=np.float32)
        np.abs(error, out=error)
        tolerance = np.maximum(total, colour[c], out=total)
        tolerance *= np.float32(CHECK_RELATIVE)
        tolerance += floor
        ratio = np.divide(error, tolerance, out=error)
        failing |= ratio > 1.0
        worst = max(worst, float(ratio.max()) if ratio.size else 0.0)
    return SumCheck(int(np.count_nonzero(failing)), int(failing.size), worst)
