"""Click options shared by commands: one option per SVGF parameter, built from its metadata.

The SVGF parameters are documented once, in ``SVGFParams`` field metadata; this module turns
each field into exactly one ``--option`` so the help text, the README table and the stored
``svgf/params`` never drift apart. Every option defaults to None: the preset supplies the
value and an explicit option overrides it.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping, Sequence
from typing import Any, TypeVar

import click

from svgf_cli.errors import UsageError
from svgf_cli.filters.params import (
    AUTO_ITERATIONS,
    AUTO_PIXEL_FILTER,
    DEFAULT_PRESET,
    PRESETS,
    SVGFParams,
    atrous_iterations_for,
    resolve_params,
)

F = TypeVar("F", bound=Callable[..., Any])


class AutoOrNumber(click.ParamType):
    """A number in ``[low, high]`` or ``auto`` (``sentinel``, resolved later: the a-trous
    count from the image size, the pixel filter from the frame's header)."""

    def __init__(self, name: str, kind: type, low: float, high: float, shown_range: str,
                 noun: str, sentinel: float) -> None:
        self.name = name
        self.kind = kind
        self.low, self.high = low, high
        self.shown_range = shown_range
        self.noun = noun
        self.sentinel = sentinel

    def convert(self, value: Any, param: click.Parameter | None, ctx: click.Context | None) -> Any:
        if value is None or isinstance(value, self.kind):
            return value
        text = str(value).strip().lower()
        if text == "auto":
            return self.kind(self.sentinel)
        try:
            number = self.kind(text)
        except ValueError:
            self.fail(f"{value!r}: expected {self.noun} or 'auto'", param, ctx)
        if not self.low <= number <= self.high:
            self.fail(f"{number}: must lie in {self.shown_range} or be 'auto'", param, ctx)
        return number


# ``N`` (0 to 12 a-trous iterations; step 4096 at most) or ``auto``.
ITERATIONS_TYPE = AutoOrNumber("N|auto", int, 0, 12, "0..12", "a number of iterations",
                               AUTO_ITERATIONS)
# ``W`` (a neighbour weight in 0..1/3; 0 = off) or ``auto``.
PIXEL_FILTER_TYPE = AutoOrNumber("W|auto", float, 0.0, 1.0 / 3.0, "0..1/3", "a weight",
                                 AUTO_PIXEL_FILTER)


def param_label(name: str, value: Any) -> str:
    """A parameter value as the user writes it (``auto`` for the automatic a-trous count
    and pixel filter)."""
    if name == "atrous_iterations" and value == AUTO_ITERATIONS:
        return "auto"
    if name == "pixel_filter" and value == AUTO_PIXEL_FILTER:
        return "auto"
    return str(value)


_CLICK_TYPES: dict[str, click.ParamType] = {"float": click.FLOAT, "int": click.INT}

# The valid range of each numeric SVGF parameter; click refuses a value outside it (exit 2)
# and shows the range in --help. A parameter missing here takes any number.
PARAM_RANGES: dict[str, click.ParamType] = {
    "alpha": click.FloatRange(0.0, 1.0, min_open=True),
    "moments_alpha": click.FloatRange(0.0, 1.0, min_open=True),
    "history_cap": click.IntRange(min=1),
    "depth_tolerance": click.FloatRange(min=0.0),
    "depth_slack": click.FloatRange(min=0.0),
    "normal_tolerance": click.FloatRange(min=0.0),
    "variance_history_threshold": click.IntRange(min=0),
    "spatial_variance_radius": click.IntRange(min=0),
    "spatial_variance_sigma_luminance": click.FloatRange(min=0.0, min_open=True),
    "atrous_iterations": ITERATIONS_TYPE,
    "feedback_iteration": click.IntRange(min=-1),
    "sigma_luminance": click.FloatRange(min=0.0, min_open=True),
    "sigma_normal": click.FloatRange(min=0.0, min_open=True),
    "sigma_depth": click.FloatRange(min=0.0, min_open=True),
    "albedo_epsilon": click.FloatRange(min=0.0, min_open=True),
    "guide_albedo_floor": click.FloatRange(0.0, 1.0),
    "firefly_clamp": click.FloatRange(min=0.0),
    "history_clamp": click.FloatRange(min=0.0),
    "spread_fireflies": click.FloatRange(min=0.0),
    "despike": click.FloatRange(min=0.0),
    "taa_alpha": click.FloatRange(0.0, 1.0, min_open=True),
    "pixel_filter": PIXEL_FILTER_TYPE,
    "antilag_radius": click.IntRange(1, 16),
    "antilag_sigma": click.FloatRange(min=0.0),
    "antilag_spatial_samples": click.FloatRange(min=1.0),
    "antilag_tolerance": click.FloatRange(min=0.0),
    "glossy_history_clamp": click.FloatRange(min=0.0),
    "glossy_sigma_luminance": click.FloatRange(min=0.0),
    "mixed_sigma_luminance": click.FloatRange(min=0.0),
}

FILTER_SECTION = "Filter parameters (each overrides its --preset value)"


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


class SectionedCommand(click.Command):
    """A click command whose --help lists its options in titled sections.

    ``sections`` is a list of ``(title, [parameter names])`` in display order; options named
    nowhere fall into ``default_section``, shown after the named sections except the ones in
    ``trailing`` (e.g. the filter parameters, which come last). Adding an option therefore
    needs at most one line here, or none.
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

    def format_options(self, ctx: click.Context, formatter: click.HelpFormatter) -> None:
        section_of = {name: title for title, names in self.sections for name in names}
        for param in self.params:
            if param.name and param.name in PARAM_FIELD_NAMES | {"preset"}:
                section_of.setdefault(param.name, FILTER_SECTION)
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


def param_fields() -> list[dataclasses.Field[Any]]:
    """The SVGFParams fields, in declaration order."""
    return list(dataclasses.fields(SVGFParams))


PARAM_FIELD_NAMES = frozenset(f.name for f in param_fields())


def option_name(field_name: str) -> str:
    """``moments_alpha`` -> ``--moments-alpha``."""
    return "--" + field_name.replace("_", "-")


def _field_type_name(f: dataclasses.Field[Any]) -> str:
    # `from __future__ import annotations` in params.py makes types strings; accept both.
    return f.type if isinstance(f.type, str) else f.type.__name__


def _param_option(f: dataclasses.Field[Any]) -> Callable[[F], F]:
    help_text = f.metadata.get("help", "")
    defaults = ", ".join(f"{name}: {param_label(f.name, getattr(p, f.name))}"
                         for name, p in PRESETS.items())
    help_text = f"{help_text} [{defaults}]"
    type_name = _field_type_name(f)
    flag = option_name(f.name)
    if type_name == "bool":
        negative = "--no-" + f.name.replace("_", "-")
        return click.option(f"{flag}/{negative}", f.name, default=None, help=help_text)
    click_type = PARAM_RANGES.get(f.name, _CLICK_TYPES.get(type_name))
    if click_type is None:
        raise TypeError(f"SVGFParams.{f.name}: unsupported type {type_name}")
    metavar = click_type.name.upper() if isinstance(click_type, AutoOrNumber) else None
    return click.option(flag, f.name, type=click_type, default=None,
                        metavar=metavar or type_name.upper(), help=help_text)


def svgf_param_options(func: F) -> F:
    """Add ``--preset`` and one option per SVGF parameter to a click command.

    The command receives ``preset`` plus one keyword per field (None when not given); pass
    them to ``params_from_options``.
    """
    for f in reversed(param_fields()):
        func = _param_option(f)(func)
    return click.option(
        "--preset",
        type=click.Choice(sorted(PRESETS)),
        default=DEFAULT_PRESET,
        show_default=True,
        help="Parameter preset: default (the paper's filter with anti-lag), paper (as"
        " published), falcor; any parameter option overrides its value.",
    )(func)


def pop_param_options(kwargs: dict[str, Any]) -> dict[str, Any]:
    """Remove the SVGF parameter keywords from ``kwargs`` and return them."""
    return {f.name: kwargs.pop(f.name, None) for f in param_fields()}


def params_from_options(preset: str, kwargs: Mapping[str, Any]) -> SVGFParams:
    """Resolve the preset plus the explicitly given parameter options.

    ``kwargs`` may hold other command keywords too; only SVGFParams fields are used.
    """
    names = {f.name for f in param_fields()}
    overrides = {k: v for k, v in kwargs.items() if k in names and v is not None}
    try:
        params = resolve_params(preset, **overrides)
    except (ValueError, TypeError) as exc:
        raise UsageError(str(exc)) from exc
    _check_ranges(params)
    return params


def _check_ranges(params: SVGFParams) -> None:
    """The checks click's range types cannot make: they involve two options."""
    if params.bidirectional and params.taa:
        raise UsageError("--taa filters the output causally; it cannot be combined with "
                         "--bidirectional")
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
