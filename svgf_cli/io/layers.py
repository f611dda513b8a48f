"""Which EXR channels hold which role (color, albedo, normal, ...), and motion conventions.

Channels are always found by name, never by position: OpenImageIO reorders EXR channels
on read (RGBA first, then Z, then the rest by layer).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from svgf_cli.errors import InputError, UsageError

# Light lobes a renderer may split its light into (signal names of the `lobes` set). Each
# has the roles <lobe>_direct, <lobe>_indirect (its light) and <lobe>_color (its reflectance).
LOBES = ("diffuse", "glossy", "transmission", "volume")
LOBE_ROLES = tuple(f"{lobe}_{part}" for lobe in LOBES for part in ("direct", "indirect", "color"))

ROLES = (
    "color",
    "direct",
    "indirect",
    "emission",
    "environment",
    *LOBE_ROLES,
    "albedo",
    "normal",
    "depth",
    "motion",
    "motion_next",
    "id",
    "alpha",
)

# Number of channels each role carries.
ROLE_WIDTH = {
    "color": 3,
    "direct": 3,
    "indirect": 3,
    "emission": 3,
    "environment": 3,
    **{role: 3 for role in LOBE_ROLES},
    "albedo": 3,
    "normal": 3,
    "depth": 1,
    "motion": 2,
    "motion_next": 2,
    "id": 1,
    "alpha": 1,
}

# Always required; a signal (direct+indirect, or color) is required on top.
REQUIRED_ROLES = ("albedo", "normal", "depth", "motion")
OPTIONAL_ROLES = ("emission", "motion_next", "id", "alpha")
# Radiance-like roles: cleaned as radiance on read (NaN/Inf and negatives to 0).
RADIANCE_ROLES = ("color", "direct", "indirect", "emission", "environment", *LOBE_ROLES)

MOTION_CONVENTIONS = ("backward-pixels", "forward-pixels", "cycles")

# Signal sets (io.signals builds them): `--signals` takes one of these or `auto`.
SIGNAL_SETS = ("lobes", "lobes-split", "direct-indirect", "combined")
SIGNAL_CHOICES = ("auto", *SIGNAL_SETS)

# Channel-name suffixes tried when an override names only a layer (``--aov normal=Normal``).
_LAYER_SUFFIXES: dict[int, tuple[tuple[str, ...], ...]] = {
    1: (("",), ("Z",), ("Y",), ("R",), ("X",)),
    2: (("X", "Y"), ("R", "G"), ("x", "y"), ("U", "V"), ("u", "v")),
    3: (("R", "G", "B"), ("X", "Y", "Z"), ("r", "g", "b"), ("x", "y", "z")),
}

Candidates = tuple[tuple[str, ...], ...]


def _rgb(layer: str) -> tuple[str, str, str]:
    return (f"{layer}.R", f"{layer}.G", f"{layer}.B")


def _xyz(layer: str) -> tuple[str, str, str]:
    return (f"{layer}.X", f"{layer}.Y", f"{layer}.Z")


def _lobes(names: dict[str, tuple[str, ...]]) -> dict[str, Candidates]:
    """Lobe roles from ``{role: (layer, ...)}`` (RGB layers); every other lobe role empty."""
    return {role: tuple(_rgb(layer) for layer in names.get(role, ())) for role in LOBE_ROLES}


# Blender Cycles' light passes (verified on Blender 4.5 renders, docs/cycles.md); `svgf trace
# --lobes` writes the same names without a view-layer prefix.
_CYCLES_LOBES = _lobes({
    "diffuse_direct": ("DiffDir",), "diffuse_indirect": ("DiffInd",), "diffuse_color": ("DiffCol",),
    "glossy_direct": ("GlossDir",), "glossy_indirect": ("GlossInd",), "glossy_color": ("GlossCol",),
    "transmission_direct": ("TransDir",), "transmission_indirect": ("TransInd",),
    "transmission_color": ("TransCol",),
    "volume_direct": ("VolumeDir",), "volume_indirect": ("VolumeInd",),
})  # fmt: skip


# Channel names per renderer (research note ecosystem-anchors.md, sections 1.6 and 2.1).
# Each role lists candidate channel tuples in order of preference.
AOV_PRESETS: dict[str, dict[str, Candidates]] = {
    # The default input convention (issue 2), also what `svgf trace` writes.
    "svgf": {
        "color": (("R", "G", "B"),),
        "direct": (_rgb("direct"),),
        "indirect": (_rgb("indirect"),),
        "emission": (_rgb("emission"),),
        "environment": (),
        **_CYCLES_LOBES,
        "albedo": (_rgb("albedo"),),
        "normal": (_xyz("N"), _rgb("N")),
        "depth": (("Z",),),
        "motion": (("motion.X", "motion.Y"),),
        # svgf trace --motion-next: forward motion to the next frame, pixels, y down.
        "motion_next": (("motion_next.X", "motion_next.Y"),),
        "id": (("id",),),
        "alpha": (("A",),),
    },
    # Blender Cycles multilayer EXR; view-layer prefixes ("ViewLayer.") are matched
    # automatically. The noisy beauty is preferred when Cycles also wrote a denoised one.
    "cycles": {
        "color": (_rgb("Noisy Image"), _rgb("Combined")),
        "direct": (_rgb("direct"),),
        "indirect": (_rgb("indirect"),),
        "emission": (_rgb("Emit"),),
        "environment": (_rgb("Env"),),
        **_CYCLES_LOBES,
        "albedo": (_rgb("Denoising Albedo"), _rgb("DiffCol")),
        # Normal is world space, Denoising Normal camera space (verified on Blender 4.5
        # renders): reprojection compares normals across frames, so camera-space normals
        # would fail it wherever the camera rotates.
        "normal": (_xyz("Normal"), _xyz("Denoising Normal")),
        "depth": (("Depth.Z",), ("Denoising Depth.Z",)),
        "motion": (("Vector.X", "Vector.Y"),),
        # Vector.ZW: current - next position, pixels, y up (docs/cycles.md, measured).
        "motion_next": (("Vector.Z", "Vector.W"),),
        "id": (("IndexOB.X",), ("IndexOB.V",)),
        "alpha": (("Noisy Image.A",), ("Combined.A",)),
    },
    # Arnold: RGBA beauty (with or without "Preserve Layer Name"), built-in direct/indirect
    # and emission AOVs, N (VECTOR), Z (FLOAT), motionvector (RGB), ID. Lobe AOVs are Arnold's
    # built-in light path expressions (Arnold User Guide, "Light Path Expression AOVs"):
    # radiance, not divided by their *_albedo (unverified: no Arnold render was seen).
    "arnold": {
        "color": (("R", "G", "B"), _rgb("RGBA")),
        "direct": (_rgb("direct"),),
        "indirect": (_rgb("indirect"),),
        "emission": (_rgb("emission"),),
        "environment": (_rgb("background"),),
        **_lobes({
            "diffuse_direct": ("diffuse_direct",), "diffuse_indirect": ("diffuse_indirect",),
            "diffuse_color": ("diffuse_albedo",),
            "glossy_direct": ("specular_direct",), "glossy_indirect": ("specular_indirect",),
            "glossy_color": ("specular_albedo",),
            "transmission_direct": ("transmission_direct",),
            "transmission_indirect": ("transmission_indirect",),
            "transmission_color": ("transmission_albedo",),
            "volume_direct": ("volume_direct",), "volume_indirect": ("volume_indirect",),
            "volume_color": ("volume_albedo",),
        }),  # fmt: skip
        "albedo": (_rgb("denoise_albedo"), _rgb("diffuse_albedo"), _rgb("albedo")),
        "normal": (_xyz("N"), _rgb("N")),
        "depth": (("Z",), ("Z.Z",), ("Z.R",)),
        "motion": (("motionvector.R", "motionvector.G"), ("motionvector.X", "motionvector.Y")),
        # No pass of its own: a bidirectional run inverts the next frame's motion.
        "motion_next": (),
        "id": (("ID",), ("ID.R",), ("id",)),
        "alpha": (("A",), ("RGBA.A",)),
    },
    # Houdini Karma written by husk: beauty C as RGBA, N, albedo, depth as Pz or depth,
    # motionvector. Names partly from memory: check with `svgf inspect`. Lobe AOVs are the
    # Karma Render Settings' extra render vars (radiance; unverified); Karma has no per-lobe
    # albedo by default, so `diffuse_albedo`/`specular_albedo` are custom LPE names (C<RD>A,
    # C<RG>A) and the G-buffer `albedo` stands in for the diffuse colour.
    "karma": {
        "color": (("R", "G", "B"), _rgb("C")),
        "direct": (_rgb("direct"),),
        "indirect": (_rgb("indirect"),),
        "emission": (_rgb("emission"), _rgb("directemission")),
        "environment": (),
        **_lobes({
            "diffuse_direct": ("directdiffuse",), "diffuse_indirect": ("indirectdiffuse",),
            "diffuse_color": ("diffuse_albedo", "albedo"),
            "glossy_direct": ("directglossyreflection",),
            "glossy_indirect": ("indirectglossyreflection",),
            "glossy_color": ("specular_albedo",),
            "volume_direct": ("directvolume",), "volume_indirect": ("indirectvolume",),
        }),  # fmt: skip
        "albedo": (_rgb("albedo"),),
        "normal": (_xyz("N"), _rgb("N")),
        "depth": (("Pz",), ("depth",), ("depth.Z",), ("Z",)),
        "motion": (("motionvector.X", "motionvector.Y"), ("motionvector.R", "motionvector.G")),
        "motion_next": (),  # derived, as for Arnold
        "id": (("objid",), ("primid",), ("id",)),
        "alpha": (("A",), ("C.A",)),
    },
}

# Where `svgf denoise` writes the denoised colour: the layer a compositing script reads as
# the beauty. Cycles filters its noisy `Noisy Image` (when Cycles' own denoiser also ran,
# `Combined` holds that denoised result) but the beauty a compositor reads is `Combined`;
# the noisy layer is passed through unchanged. Other presets write over the colour role.
OUTPUT_COLOUR: dict[str, Candidates] = {
    "cycles": (_rgb("Combined"), _rgb("Noisy Image")),
}

# Whether a preset's lobe light passes are stored divided by their colour pass (Cycles: the
# light passes times the colour passes rebuild Combined, docs/cycles.md) or as radiance
# (Arnold's and Karma's light path expression AOVs).
LOBE_LIGHT_DIVIDED = {"svgf": True, "cycles": True, "arnold": False, "karma": False}

# Whether a preset's `direct` layer holds the emission seen at the primary hit (`svgf trace`
# writes it so); Arnold's built-in `direct` is C[DSV]L, without the camera-visible emission.
EMISSION_IN_DIRECT = {"svgf": True, "cycles": True, "arnold": False, "karma": True}

# The motion convention each preset implies unless --motion-convention says otherwise.
# Arnold and Karma write shutter-interval motion-blur vectors (towards the next frame);
# this mapping is our best reading of their docs, marked [verify] in docs/inputs.md.
PRESET_MOTION_CONVENTION = {
    "svgf": "backward-pixels",
    "cycles": "cycles",
    "arnold": "forward-pixels",
    "karma": "forward-pixels",
}


@dataclass
class LayerMapping:
    """Ordered candidate channel tuples per role, plus the motion convention to apply."""

    candidates: dict[str, Candidates]
    preset: str = "svgf"
    motion_convention: str = "backward-pixels"
    overridden: tuple[str, ...] = ()
    # The signal set asked for (`--signals`: auto or one of io.signals.SIGNAL_SETS), and
    # whether it is fixed: a run decides on its first frame, then reads every frame with
    # that set (a frame failing the light-pass check then only warns).
    signals: str = "auto"
    signals_fixed: bool = False

    def describe(self) -> str:
        """Multi-line ``role: A,B,C | D,E,F`` listing, for logs and `svgf inspect`."""
        lines = [f"preset {self.preset}, motion convention {self.motion_convention}"]
        for role in ROLES:
            options = self.candidates.get(role, ())
            shown = " | ".join(",".join(c) for c in options) if options else "(none)"
            mark = " (--aov)" if role in self.overridden else ""
            lines.append(f"{role:>21}: {shown}{mark}")
        return "\n".join(lines)


def parse_aov_override(text: str) -> tuple[str, tuple[str, ...]]:
    """``"motion=Vector.X,Vector.Y"`` -> ``("motion", ("Vector.X", "Vector.Y"))``.

    A single name without channels for a multi-channel role (``normal=Normal``) is a layer
    name; `build_mapping` expands it to the usual suffixes. ``role=none`` disables a role.
    """
    role, sep, value = text.partition("=")
    role = role.strip().lower()
    if not sep or not role:
        raise UsageError(
            f"bad --aov {text!r}: expected ROLE=CHANNELS, e.g. motion=Vector.X,Vector.Y"
        )
    if role not in ROLES:
        raise UsageError(f"bad --aov {text!r}: unknown role {role!r} (roles: {', '.join(ROLES)})")
    value = value.strip()
    if value.lower() in ("", "none"):
        return role, ()
    names = tuple(name.strip() for name in value.split(","))
    if any(not name for name in names):
        raise UsageError(f"bad --aov {text!r}: empty channel name")
    width = ROLE_WIDTH[role]
    if len(names) != width and len(names) != 1:
        raise UsageError(
            f"bad --aov {text!r}: {role} needs {width} channel(s) or one layer name, "
            f"got {len(names)}"
        )
    return role, names


def _expand_layer(role: str, names: tuple[str, ...]) -> Candidates:
    """Candidate tuples for an override: exact channels, or a layer name plus suffixes."""
    width = ROLE_WIDTH[role]
    if not names:
        return ()
    if len(names) == width and (width > 1 or "." in names[0]):
        return (names,)
    layer = names[0]
    expanded = [
        tuple(f"{layer}.{s}" if s else layer for s in suffixes)
        for suffixes in _LAYER_SUFFIXES[width]
    ]
    # A one-channel role named without a dot is also tried as the bare channel name.
    return tuple(dict.fromkeys(expanded))


def build_mapping(
    preset: str = "svgf",
    overrides: Mapping[str, str] | Iterable[str] | None = None,
    motion_convention: str | None = None,
    signals: str = "auto",
) -> LayerMapping:
    """The layer mapping of ``preset`` with ``--aov`` overrides applied.

    ``overrides`` is either ``{role: "CH1,CH2"}`` or an iterable of ``"role=CH1,CH2"`` texts
    (the raw repeated ``--aov`` option). ``motion_convention`` None keeps the preset's.
    ``signals`` is the signal set asked for (``--signals``).
    """
    if signals not in SIGNAL_CHOICES:
        choices = ", ".join(SIGNAL_CHOICES)
        raise UsageError(f"unknown signal set {signals!r} (choose from {choices})")
    if preset not in AOV_PRESETS:
        raise UsageError(f"unknown AOV preset {preset!r} (choose from {', '.join(AOV_PRESETS)})")
    candidates = dict(AOV_PRESETS[preset])
    parsed: list[tuple[str, tuple[str, ...]]] = []
    if overrides is not None:
        if isinstance(overrides, Mapping):
            parsed = [parse_aov_override(f"{r}={v}") for r, v in overrides.items()]
        else:
            parsed = [parse_aov_override(text) for text in overrides]
    for role, names in parsed:
        candidates[role] = _expand_layer(role, names)
    convention = motion_convention or PRESET_MOTION_CONVENTION[preset]
    if convention not in MOTION_CONVENTIONS:
        choices = ", ".join(MOTION_CONVENTIONS)
        raise UsageError(f"unknown motion convention {convention!r} (choose from {choices})")
    return LayerMapping(
        candidates=candidates,
        preset=preset,
        motion_convention=convention,
        overridden=tuple(dict.fromkeys(role for role, _ in parsed)),
        signals=signals,
    )


@dataclass
class ResolvedLayers:
    """Role -> the file's channel names for it (None when absent), and what is missing.

    ``plan`` is the signal set the file is read as (an ``io.signals.SignalPlan``, set by
    whoever planned it); without one the legacy choice applies (direct+indirect, else color).
    """

    channels: dict[str, tuple[str, ...] | None]
    missing: dict[str, str] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)
    # The role's other candidates present in the file, in the mapping's order after the
    # chosen one: a reader may fall back to them when the chosen channels hold nothing.
    alternatives: dict[str, list[tuple[str, ...]]] = field(default_factory=dict)
    plan: Any = None
    requested_signals: str = "auto"

    def __getitem__(self, role: str) -> tuple[str, ...] | None:
        return self.channels.get(role)

    @property
    def split(self) -> bool:
        """True when direct and indirect are both present."""
        return self["direct"] is not None and self["indirect"] is not None

    @property
    def signal_roles(self) -> tuple[str, ...]:
        """The roles holding the filtered signals' light."""
        if self.plan is not None:
            return tuple(self.plan.light_roles())
        if self.split:
            return ("direct", "indirect")
        return ("color",) if self["color"] is not None else ()

    def roles_to_read(self) -> list[str]:
        """Roles whose channels a reader needs: the signals, the G-buffer, optional extras."""
        signal_roles = self.plan.roles() if self.plan is not None else self.signal_roles
        wanted = [*signal_roles, *REQUIRED_ROLES, *OPTIONAL_ROLES]
        return [role for role in dict.fromkeys(wanted) if self[role] is not None]

    def describe(self) -> str:
        used = set(self.plan.roles()) if self.plan is not None else set(self.signal_roles)
        lines = []
        for role in ROLES:
            names = self[role]
            quiet = role in LOBE_ROLES or role == "environment"  # shown only when present
            if names is not None:
                signal_like = role in RADIANCE_ROLES and role != "emission"
                unused = "  (present, not used)" if signal_like and role not in used else ""
                lines.append(f"{role:>21}: {', '.join(names)}{unused}")
            elif role in self.missing:
                lines.append(f"{role:>21}: MISSING (looked for {self.missing[role]})")
            elif not quiet:
                lines.append(f"{role:>21}: -")
        if self.plan is not None:
            lines.extend(self.plan.describe(self, self.requested_signals))
        else:
            lines.append(f"  signals: {' + '.join(self.signal_roles) or 'none'}")
        lines.extend(f"  note: {note}" for note in self.notes)
        return "\n".join(lines)


def _match_tuple(
    wanted: tuple[str, ...], present: set[str], by_suffix: dict[str, list[str]]
) -> tuple[tuple[str, ...] | None, str | None]:
    """Find ``wanted`` in the file: exactly, or under one unambiguous dotted prefix.

    Prefix matching applies only to names that already have a layer component
    (``Combined.R`` matches ``ViewLayer.Combined.R``); a bare ``R`` never matches
    ``albedo.R``. Returns (channels, ambiguity note).
    """
    if all(name in present for name in wanted):
        return wanted, None
    if not all("." in name for name in wanted):
        return None, None
    prefixes = {full[: len(full) - len(wanted[0])] for full in by_suffix.get(wanted[0], [])}
    hits = sorted(p for p in prefixes if all(p + name in present for name in wanted))
    if len(hits) == 1:
        return tuple(hits[0] + name for name in wanted), None
    if len(hits) > 1:
        shown = ", ".join(h + wanted[0] for h in hits)
        return None, f"{','.join(wanted)} is ambiguous ({shown})"
    return None, None


def _suffix_index(channel_names: Iterable[str]) -> dict[str, list[str]]:
    """Every whole-component dotted suffix of every name -> names ending in it."""
    index: dict[str, list[str]] = {}
    for name in channel_names:
        parts = name.split(".")
        for start in range(1, len(parts)):
            index.setdefault(".".join(parts[start:]), []).append(name)
    return index


def match_channels(wanted: tuple[str, ...], channel_names: Sequence[str]) -> tuple[str, ...] | None:
    """``wanted`` as the file names it (exactly, or under one unambiguous view-layer
    prefix, as roles are matched), or None."""
    found, _ = _match_tuple(wanted, set(channel_names), _suffix_index(channel_names))
    return found


def _format_have(channel_names: Sequence[str], limit: int = 40) -> str:
    shown = ", ".join(channel_names[:limit])
    if len(channel_names) > limit:
        shown += f", ... ({len(channel_names) - limit} more)"
    return shown or "(no channels)"


def resolve_layers(
    mapping: LayerMapping,
    channel_names: Sequence[str],
    path: str | None = None,
    *,
    strict: bool = True,
) -> ResolvedLayers:
    """Map each role to channels present in the file.

    Required: albedo, normal, depth, motion, and direct+indirect or color. With ``strict``
    a missing one raises InputError: ``<path>: missing channel(s) for normal (looked for
    N.X,N.Y,N.Z or N.R,N.G,N.B); file has: R, G, B, ...``. Without it the gaps are recorded
    in ``missing`` (for `svgf inspect`).
    """
    present = set(channel_names)
    by_suffix = _suffix_index(channel_names)
    channels: dict[str, tuple[str, ...] | None] = {}
    alternatives: dict[str, list[tuple[str, ...]]] = {}
    looked_for: dict[str, str] = {}
    notes: list[str] = []
    for role in ROLES:
        options = mapping.candidates.get(role, ())
        looked_for[role] = " or ".join(",".join(c) for c in options) or "(disabled)"
        channels[role] = None
        for wanted in options:
            found, ambiguity = _match_tuple(wanted, present, by_suffix)
            if channels[role] is None:
                if ambiguity:
                    notes.append(f"{role}: {ambiguity}")
                channels[role] = found
            elif found is not None and found != channels[role]:
                alternatives.setdefault(role, []).append(found)

    missing: dict[str, str] = {}
    for role in REQUIRED_ROLES:
        if channels[role] is None:
            missing[role] = looked_for[role]
    has_split = channels["direct"] is not None and channels["indirect"] is not None
    if not has_split and channels["color"] is None:
        missing["color"] = (
            f"{looked_for['color']}, or direct ({looked_for['direct']}) "
            f"with indirect ({looked_for['indirect']})"
        )
    elif not has_split and (channels["direct"] is None) != (channels["indirect"] is None):
        lone = "direct" if channels["direct"] is not None else "indirect"
        notes.append(f"{lone} found without its partner: filtering color as one signal")

    resolved = ResolvedLayers(channels=channels, missing=missing, notes=notes,
                              alternatives=alternatives)
    if strict and missing:
        parts = [f"{role} (looked for {where})" for role, where in missing.items()]
        extra = f" [{'; '.join(notes)}]" if notes else ""
        raise InputError(
            f"missing channel(s) for {'; '.join(parts)}; file has: "
            f"{_format_have(list(channel_names))}{extra}",
            path,
        )
    return resolved


def to_backward_pixels(xy: np.ndarray, convention: str) -> np.ndarray:
    """Convert a ``(2, H, W)`` motion field to the canonical backward, pixel, y-down form.

    Already canonical float32 input is returned as is (not copied).

    * ``backward-pixels``: already canonical (previous position = current + v);
    * ``forward-pixels``: v points from the previous to the current position
      (previous = current - v), so backward = -v;
    * ``cycles``: Blender's ``Vector.XY`` is previous - current in pixels with +Y up
      (ecosystem-anchors.md 1.6), so backward = (X, -Y) with our rows running down.
    """
    xy = np.asarray(xy, dtype=np.float32)
    if xy.ndim != 3 or xy.shape[0] != 2:
        raise ValueError(f"motion must be (2, H, W), got {xy.shape}")
    if convention == "backward-pixels":
        return np.ascontiguousarray(xy, dtype=np.float32)
    if convention == "forward-pixels":
        return np.ascontiguousarray(-xy, dtype=np.float32)
    if convention == "cycles":
        out = np.empty_like(xy, dtype=np.float32)
        out[0] = xy[0]
        np.negative(xy[1], out=out[1])
        return out
    raise ValueError(
        f"unknown motion convention {convention!r} (choose from {', '.join(MOTION_CONVENTIONS)})"
    )


def to_next_pixels(xy: np.ndarray, convention: str) -> np.ndarray:
    """Convert a ``(2, H, W)`` motion-to-the-next-frame field to the canonical forward form
    (the surface at pixel centre ``p`` is at ``p + v`` in the next frame, pixels, y down).

    The next-frame channels come with the motion role's convention: ``cycles`` reads
    Blender's ``Vector.ZW`` (current - next, pixels, +Y up), so forward = (-Z, W); every
    other convention reads them as already forward, in pixels, y down (what ``svgf trace
    --motion-next`` writes).
    """
    xy = np.asarray(xy, dtype=np.float32)
    if xy.ndim != 3 or xy.shape[0] != 2:
        raise ValueError(f"motion_next must be (2, H, W), got {xy.shape}")
    if convention == "cycles":
        out = np.empty_like(xy, dtype=np.float32)
        np.negative(xy[0], out=out[0])
        out[1] = xy[1]
        return out
    if convention in MOTION_CONVENTIONS:
        return np.ascontiguousarray(xy, dtype=np.float32)
    raise ValueError(
        f"unknown motion convention {convention!r} (choose from {', '.join(MOTION_CONVENTIONS)})"
    )


def _output_colour_candidates(mapping: LayerMapping) -> Candidates:
    if "color" in mapping.overridden:
        return mapping.candidates.get("color", ())
    return OUTPUT_COLOUR.get(mapping.preset, mapping.candidates.get("color", ()))


def describe_output_colour(mapping: LayerMapping) -> str:
    """``A,B,C or D,E,F``: the channel names the denoised colour may be written under."""
    return " or ".join(",".join(c) for c in _output_colour_candidates(mapping)) or "(none)"


def resolve_output_colour(
    mapping: LayerMapping, channel_names: Sequence[str]
) -> tuple[str, str, str] | None:
    """The input channels the denoised colour replaces (None: the file has no colour layer;
    the writer then adds ``R,G,B``). Same name matching as `resolve_layers`."""
    present = set(channel_names)
    by_suffix = _suffix_index(channel_names)
    for wanted in _output_colour_candidates(mapping):
        if len(wanted) != 3:
            continue
        found, _ = _match_tuple(wanted, present, by_suffix)
        if found is not None:
            return (found[0], found[1], found[2])
    return None
