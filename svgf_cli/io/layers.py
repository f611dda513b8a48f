"""Which EXR channels hold which role (color, albedo, normal, ...), and motion conventions.

Channels are always found by name, never by position: OpenImageIO reorders EXR channels
on read (RGBA first, then Z, then the rest by layer).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from svgf_cli.errors import InputError, UsageError

ROLES = (
    "color",
    "direct",
    "indirect",
    "emission",
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

MOTION_CONVENTIONS = ("backward-pixels", "forward-pixels", "cycles")

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


# Channel names per renderer (research note ecosystem-anchors.md, sections 1.6 and 2.1).
# Each role lists candidate channel tuples in order of preference.
AOV_PRESETS: dict[str, dict[str, Candidates]] = {
    # The default input convention (issue 2), also what `svgf trace` writes.
    "svgf": {
        "color": (("R", "G", "B"),),
        "direct": (_rgb("direct"),),
        "indirect": (_rgb("indirect"),),
        "emission": (_rgb("emission"),),
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
    # and emission AOVs, N (VECTOR), Z (FLOAT), motionvector (RGB), ID.
    "arnold": {
        "color": (("R", "G", "B"), _rgb("RGBA")),
        "direct": (_rgb("direct"),),
        "indirect": (_rgb("indirect"),),
        "emission": (_rgb("emission"),),
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
    # motionvector. Names partly from memory: check with `svgf inspect`.
    "karma": {
        "color": (("R", "G", "B"), _rgb("C")),
        "direct": (_rgb("direct"),),
        "indirect": (_rgb("indirect"),),
        "emission": (_rgb("emission"), _rgb("directemission")),
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

    def describe(self) -> str:
        """Multi-line ``role: A,B,C | D,E,F`` listing, for logs and `svgf inspect`."""
        lines = [f"preset {self.preset}, motion convention {self.motion_convention}"]
        for role in ROLES:
            options = self.candidates.get(role, ())
            shown = " | ".join(",".join(c) for c in options) if options else "(none)"
            mark = " (--aov)" if role in self.overridden else ""
            lines.append(f"{role:>9}: {shown}{mark}")
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
) -> LayerMapping:
    """The layer mapping of ``preset`` with ``--aov`` overrides applied.

    ``overrides`` is either ``{role: "CH1,CH2"}`` or an iterable of ``"role=CH1,CH2"`` texts
    (the raw repeated ``--aov`` option). ``motion_convention`` None keeps the preset's.
    """
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
    )


@dataclass
class ResolvedLayers:
    """Role -> the file's channel names for it (None when absent), and what is missing."""

    channels: dict[str, tuple[str, ...] | None]
    missing: dict[str, str] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)

    def __getitem__(self, role: str) -> tuple[str, ...] | None:
        return self.channels.get(role)

    @property
    def split(self) -> bool:
        """True when direct and indirect are both present (filtered as two signals)."""
        return self["direct"] is not None and self["indirect"] is not None

    @property
    def signal_roles(self) -> tuple[str, ...]:
        if self.split:
            return ("direct", "indirect")
        return ("color",) if self["color"] is not None else ()

    def roles_to_read(self) -> list[str]:
        """Roles whose channels a reader needs: the signals, the G-buffer, optional extras."""
        wanted = [*self.signal_roles, *REQUIRED_ROLES, *OPTIONAL_ROLES]
        return [role for role in wanted if self[role] is not None]

    def describe(self) -> str:
        lines = []
        for role in ROLES:
            names = self[role]
            if names is not None:
                unused = role in ("color", "direct", "indirect") and role not in self.signal_roles
                used = "  (present, not used)" if unused else ""
                lines.append(f"{role:>9}: {', '.join(names)}{used}")
            elif role in self.missing:
                lines.append(f"{role:>9}: MISSING (looked for {self.missing[role]})")
            else:
                lines.append(f"{role:>9}: -")
        signals = " + ".join(self.signal_roles) or "none"
        lines.append(f"  signals: {signals}")
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
    looked_for: dict[str, str] = {}
    notes: list[str] = []
    for role in ROLES:
        options = mapping.candidates.get(role, ())
        looked_for[role] = " or ".join(",".join(c) for c in options) or "(disabled)"
        channels[role] = None
        for wanted in options:
            found, ambiguity = _match_tuple(wanted, present, by_suffix)
            if ambiguity:
                notes.append(f"{role}: {ambiguity}")
            if found is not None:
                channels[role] = found
                break

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

    resolved = ResolvedLayers(channels=channels, missing=missing, notes=notes)
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
