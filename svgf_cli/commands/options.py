"""Click options shared by commands: the SVGF parameters, the frame/chunk options, --help
sections.

Each SVGF parameter is declared once, in ``SVGFParams`` field metadata (help, group, valid
range: ``svgf_cli.filters.params``); this module only turns that into click types. The
documented way to set a parameter is ``--set NAME=VALUE`` (repeatable); each parameter also
keeps its own ``--option`` as a hidden alias (not listed in --help), so existing farm
templates, scripts and docs keep working. ``svgf params`` (and ``svgf denoise
--list-params``) lists the parameters with ``parameter_listing``. Every parameter defaults
to None: the preset supplies the value and an explicit option overrides it.
"""

from __future__ import annotations

import dataclasses
import difflib
import textwrap
from collections.abc import Callable, Mapping, Sequence
from typing import Any, TypeVar

import click

from svgf_cli.errors import UsageError
from svgf_cli.farm.plan import DEFAULT_WARMUP
from svgf_cli.filters.params import (
    AUTO_ITERATIONS,
    AUTO_PIXEL_FILTER,
    DEFAULT_PRESET,
    DEPARTURES,
    GROUPS,
    PRESETS,
    Range,
    SVGFParams,
    atrous_iterations_for,
    check_params,
    param_fields,
    resolve_params,
)

F = TypeVar("F", bound=Callable[..., Any])

class AutoOrNumber(click.ParamType):
    """A number in a declared ``Range`` that also takes ``auto`` (its sentinel, resolved
    later: the a-trous count from the image size, the pixel filter from the frame's header)
    or an ``off`` value outside the range (despike 0)."""

    def __init__(self, kind: type, valid: Range) -> None:
        self.kind = kind
        self.valid = valid
        self.name = f"{kind.__name__.upper()}|auto" if valid.auto is not None else "FLOAT"

    def convert(self, value: Any, param: click.Parameter | None, ctx: click.Context | None) -> Any:
        if value is None or (isinstance(value, self.kind) and not isinstance(value, bool)):
            return value
        text = str(value).strip().lower()
        valid = self.valid
        if text == "auto" and valid.auto is not None:
            return self.kind(valid.auto)
        try:
            number = self.kind(text)
        except ValueError:
            either = " or 'auto'" if valid.auto is not None else ""
            self.fail(f"{value!r}: expected {valid.noun}{either}", param, ctx)
        if valid.auto is not None and not valid.in_bounds(number):
            self.fail(f"{number}: must lie in {valid.bounds_text()} or be 'auto'", param, ctx)
        if not valid.contains(number):
            self.fail(f"{number}: must be {valid.text()}", param, ctx)
        return number


def _type_name(f: dataclasses.Field[Any]) -> str:
    # `from __future__ import annotations` in params.py makes types strings; accept both.
    return f.type if isinstance(f.type, str) else f.type.__name__


def param_type(f: dataclasses.Field[Any]) -> click.ParamType:
    """The click type of one parameter, from its declared range (booleans: click.BOOL)."""
    type_name = _type_name(f)
    valid: Range | None = f.metadata["valid"]
    if type_name == "bool":
        return click.BOOL
    kind = {"int": int, "float": float}[type_name]
    if valid is None:
        return click.INT if kind is int else click.FLOAT
    if valid.auto is not None or valid.off is not None:
        return AutoOrNumber(kind, valid)
    if kind is int:
        return click.IntRange(valid.low, valid.high, min_open=valid.low_open,
                              max_open=valid.high_open)
    low, high = (None if b is None else float(b) for b in (valid.low, valid.high))
    return click.FloatRange(low, high, min_open=valid.low_open, max_open=valid.high_open)


PARAM_TYPES: dict[str, click.ParamType] = {f.name: param_type(f) for f in param_fields()}
PARAM_FIELD_NAMES = frozenset(PARAM_TYPES)


def param_label(name: str, value: Any) -> str:
    """A parameter value as the user writes it (``auto`` for the automatic a-trous count,
    pixel filter and edge filter; booleans as on/off in listings are the caller's choice)."""
    if name == "atrous_iterations" and value == AUTO_ITERATIONS:
        return "auto"
    if name in ("pixel_filter", "edge_filter") and value == AUTO_PIXEL_FILTER:
        return "auto"
    return str(value)


def value_text(f: dataclasses.Field[Any]) -> str:
    """What ``--set NAME=VALUE`` takes for field ``f``: ``true|false``, ``float in (0, 1]``."""
    if _type_name(f) == "bool":
        return "true|false (on|off, 1|0)"
    valid: Range | None = f.metadata["valid"]
    if valid is None:
        return _type_name(f)
    text = valid.text()
    joint = ", " if valid.off is not None else " " if text[0] in "<>" else " in "
    return f"{_type_name(f)}{joint}{text}"


FILTER_SECTION = "Filter parameters (each overrides its --preset value)"


# --- --set NAME=VALUE ------------------------------------------------------------------


_BOOLEANS = {"true": True, "on": True, "1": True, "false": False, "off": False, "0": False}


def _parse_setting(item: str, param: click.Parameter, ctx: click.Context) -> tuple[str, Any]:
    name, sep, text = item.partition("=")
    name = name.strip().replace("-", "_")
    if not sep or not name:
        raise click.BadParameter(f"{item!r}: expected NAME=VALUE (svgf params lists the names)",
                                 ctx, param)
    if name not in PARAM_TYPES:
        close = difflib.get_close_matches(name, PARAM_TYPES, n=1)
        hint = f" (did you mean {close[0]}?)" if close else ""
        raise click.BadParameter(f"no parameter {name!r}{hint}; svgf params lists them",
                                 ctx, param)
    f = SVGFParams.__dataclass_fields__[name]
    value = text.strip()
    if PARAM_TYPES[name] is click.BOOL:
        if value.lower() not in _BOOLEANS:
            raise click.BadParameter(f"{name}: {value!r} is not {value_text(f)}", ctx, param)
        return name, _BOOLEANS[value.lower()]
    try:
        return name, PARAM_TYPES[name].convert(value, param, ctx)
    except click.BadParameter as exc:
        reason = exc.message.rstrip(".")
        raise click.BadParameter(f"{name}: {reason} ({name} takes {value_text(f)})",
                                 ctx, param) from None


def _settings_callback(ctx: click.Context, param: click.Parameter,
                       items: Sequence[str]) -> dict[str, Any]:
    """``--set`` values as {field name: converted value}; a later one wins."""
    return dict(_parse_setting(item, param, ctx) for item in items or ())


def _list_params_callback(ctx: click.Context, param: click.Parameter, value: bool) -> None:
    if value and not ctx.resilient_parsing:
        click.echo(parameter_listing(), nl=False)
        ctx.exit()


# Parameters that choose a run mode rather than tune the filter: their flag stays in --help.
SHOWN_PARAMETERS = ("bidirectional", "warm_start")


def _hidden_param_option(f: dataclasses.Field[Any]) -> Callable[[F], F]:
    """Today's ``--option`` per parameter, kept as a hidden alias of ``--set`` (shown in
    --help only for the run modes of ``SHOWN_PARAMETERS``)."""
    flag = "--" + f.name.replace("_", "-")
    hidden = f.name not in SHOWN_PARAMETERS
    help_text = f.metadata["help"] if not hidden else None
    if _type_name(f) == "bool":
        negative = "--no-" + f.name.replace("_", "-")
        return click.option(f"{flag}/{negative}", f.name, default=None, hidden=hidden,
                            help=help_text)
    return click.option(flag, f.name, type=PARAM_TYPES[f.name], default=None, hidden=hidden,
                        help=help_text)


def svgf_param_options(func: F) -> F:
    """Add ``--preset``, ``--set NAME=VALUE``, ``--list-params`` and the hidden
    per-parameter options to a click command.

    The command receives ``preset``, ``settings`` (a dict) and one keyword per field (None
    when not given); pass them all to ``params_from_options``.
    """
    for f in reversed(param_fields()):
        func = _hidden_param_option(f)(func)
    func = click.option(
        "--list-params", is_flag=True, expose_value=False, is_eager=True,
        callback=_list_params_callback,
        help="List every filter parameter (group, range, each preset's value) and exit.",
    )(func)
    func = click.option(
        "--set", "settings", multiple=True, metavar="NAME=VALUE", callback=_settings_callback,
        help="Set one filter parameter, e.g. --set history_clamp=2 --set antilag=off "
        "(repeatable; auto where the range says so); svgf params lists them.",
    )(func)
    return click.option(
        "--preset",
        type=click.Choice(sorted(PRESETS)),
        default=DEFAULT_PRESET,
        show_default=True,
        help="Parameter preset: default (the paper's filter with anti-lag and the departures "
        "svgf params --preset default lists), paper (as published), falcor.",
    )(func)


def pop_param_options(kwargs: dict[str, Any]) -> dict[str, Any]:
    """Remove the SVGF parameter keywords (and ``settings``) from ``kwargs``; return them."""
    popped = {name: kwargs.pop(name, None) for name in PARAM_FIELD_NAMES}
    popped["settings"] = kwargs.pop("settings", None)
    return popped


def params_from_options(preset: str, kwargs: Mapping[str, Any]) -> SVGFParams:
    """Resolve the preset plus the explicitly given parameters (``--set`` and the hidden
    per-parameter options; the same parameter given both ways is refused).

    ``kwargs`` may hold other command keywords too; only SVGFParams fields and ``settings``
    are used.
    """
    overrides = {k: v for k, v in kwargs.items() if k in PARAM_FIELD_NAMES and v is not None}
    settings = kwargs.get("settings") or {}
    for name, value in settings.items():
        if name in overrides and overrides[name] != value:
            flag = "--" + name.replace("_", "-")
            raise UsageError(f"{name} is given twice: {flag} {overrides[name]} and --set "
                             f"{name}={param_label(name, value)}")
    try:
        params = resolve_params(preset, **{**overrides, **settings})
        check_params(params)
    except (ValueError, TypeError) as exc:
        raise UsageError(str(exc)) from exc
    _check_combinations(params)
    return params


def _check_combinations(params: SVGFParams) -> None:
    """The checks a range cannot make: they involve two parameters."""
    # With auto, the smallest count any image gets (that of a 1x1 image) bounds the index.
    iterations = atrous_iterations_for(params, 1, 1)
    if not -1 <= params.feedback_iteration < max(iterations, 1):
        raise UsageError(
            f"--feedback-iteration {params.feedback_iteration}: must be -1 or an iteration "
            f"index below --atrous-iterations ({param_label('atrous_iterations', iterations)})"
        )


def describe_params(params: SVGFParams) -> str:
    """One line of every resolved parameter, for the start-up log."""
    return " ".join(f"{f.name}={param_label(f.name, getattr(params, f.name))}"
                    for f in param_fields())


# --- the parameter listing (svgf params, svgf denoise --list-params) --------------------


def _shown(name: str, value: Any) -> str:
    if isinstance(value, bool):
        return "on" if value else "off"
    return param_label(name, value)


def _field_entry(f: dataclasses.Field[Any], presets: Sequence[str], width: int) -> list[str]:
    """One parameter: name and range, each preset's value (with the reason where it departs
    from the paper's), and its meaning."""
    indent = " " * 6
    values = ", ".join(f"{p} {_shown(f.name, getattr(PRESETS[p], f.name))}" for p in presets)
    lines = [f"  {f.name} = {value_text(f)}", f"{indent}{values}"]
    for preset in presets:
        for departure in DEPARTURES[preset]:
            if departure.name == f.name:
                lines += textwrap.wrap(f"why {preset}: {departure.reason}", width,
                                       initial_indent=indent, subsequent_indent=indent + "  ",
                                       break_long_words=False, break_on_hyphens=False)
    lines += textwrap.wrap(f.metadata["help"], width, initial_indent=indent,
                           subsequent_indent=indent, break_on_hyphens=False)
    return lines


def parameter_listing(preset: str | None = None, group: str | None = None,
                      width: int = 78) -> str:
    """Every filter parameter (or one preset's, one group's): by group, its range, the
    presets' values, the reasons a preset departs from the paper, and its meaning. The one
    place this text is made (``svgf params``, ``svgf denoise --list-params``)."""
    presets = [preset] if preset else list(PRESETS)
    lines = [f"Set with --set NAME=VALUE (repeatable). Values: {', '.join(presets)}."]
    for key, title in GROUPS.items():
        if group is not None and key != group:
            continue
        lines += ["", f"{key}: {title}"]
        for f in param_fields():
            if f.metadata["group"] == key:
                lines += _field_entry(f, presets, width)
    return "\n".join(lines) + "\n"


# --- frames, warm-up and chunks (denoise and plan) ---------------------------------------


class WarmupType(click.ParamType):
    """``N`` (a frame count >= 0) or ``all`` (None: replay from the first frame)."""

    name = "N|all"

    def convert(self, value: Any, param: click.Parameter | None, ctx: click.Context | None) -> Any:
        if value is None or isinstance(value, int):
            return value
        text = str(value).strip().lower()
        if text == "all":
            return None
        try:
            count = int(text)
        except ValueError:
            self.fail(f"{value!r}: expected a number of frames or 'all'", param, ctx)
        if count < 0:
            self.fail(f"{count}: must be >= 0 or 'all'", param, ctx)
        return count


WARMUP = WarmupType()


def warmup_label(warmup: int | None) -> str:
    """The ``--warmup`` value as written in logs, plans and ``svgf/warmup``."""
    return "all" if warmup is None else str(warmup)


def frame_options(*, plan: bool) -> Callable[[F], F]:
    """``-f/--frames``, ``--warmup`` and ``--chunk-size``, declared once for ``denoise``
    and ``plan`` (``plan=True``: --frames and --chunk-size are required there).

    The warm-up default is ``DEFAULT_WARMUP`` for both. The one place it differs is by design
    (docs/farm.md, "A bounded default warm-up for frame ranges"): ``denoise`` without
    --frames runs the whole sequence and replays from its first frame (``all``, exact); its
    ``_resolve_warmup`` applies that when --warmup was not given.
    """
    where = "" if plan else " with --frames, else all (the whole sequence)"

    def decorate(func: F) -> F:
        func = click.option(
            "--chunk-size", type=click.IntRange(min=1), required=plan, default=None,
            metavar="N", help="Output frames per chunk (one farm task each); each chunk "
            "replays its own warm-up.",
        )(func)
        func = click.option(
            "--warmup", type=WARMUP, default=DEFAULT_WARMUP, metavar="N|all",
            help="Frames processed, not written, before each chunk's first output frame; "
            "'all' replays from the first frame (bit-identical to one sequential run) "
            f"[default: {DEFAULT_WARMUP}{where}].",
        )(func)
        return click.option(
            "-f", "--frames", "frames_spec", required=plan, metavar="SPEC",
            help="Frames to write: 1001-1100, 1,5,7-9, 1001-1100x2"
            + ("." if plan else " [default: all on disk]."),
        )(func)

    return decorate


# --- --help in sections ------------------------------------------------------------------


class SectionedCommand(click.Command):
    """A click command whose --help lists its options in titled sections.

    ``sections`` is a list of ``(title, [parameter names])`` in display order; options named
    nowhere fall into ``default_section``, shown after the named sections except the ones in
    ``trailing`` (e.g. the filter parameters, which come last). Adding an option therefore
    needs at most one line here, or none. Hidden options (the per-parameter aliases of
    --set) are not listed.
    """

    def __init__(
        self,
        *args: Any,
        sections: Sequence[tuple[str, Sequence[str]]] = (),
        trailing: Sequence[str] = (FILTER_SECTION,),
        default_section: str = "Other options",
        **kwargs: Any,
    ) -> None:
        super().__init__(*args, **kwargs)
        self.sections = list(sections)
        self.trailing = list(trailing)
        self.default_section = default_section

    def _section_of(self) -> dict[str, str]:
        section_of = {name: title for title, names in self.sections for name in names}
        for name in ("preset", "settings", "list_params"):
            section_of.setdefault(name, FILTER_SECTION)
        return section_of

    def format_options(self, ctx: click.Context, formatter: click.HelpFormatter) -> None:
        section_of = self._section_of()
        titles = [t for t, _ in self.sections if t not in self.trailing]
        titles += [self.default_section, *self.trailing]
        rows: dict[str, list[tuple[str, str]]] = {title: [] for title in titles}
        order = {name: i for _, names in self.sections for i, name in enumerate(names)}
        params = sorted(
            (p for p in self.get_params(ctx) if isinstance(p, click.Option)),
            key=lambda p: order.get(p.name or "", len(order)),
        )
        for param in params:
            record = param.get_help_record(ctx)
            if record is not None:
                title = section_of.get(param.name or "", self.default_section)
                rows.setdefault(title, []).append(record)
        for title, records in rows.items():
            if records:
                with formatter.section(title):
                    formatter.write_dl(records)
