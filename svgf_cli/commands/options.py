"""Click options shared by commands: one option per SVGF parameter, built from its metadata.

The SVGF parameters are documented once, in ``SVGFParams`` field metadata; this module turns
each field into exactly one ``--option`` so the help text, the README table and the stored
``svgf/params`` never drift apart. Every option defaults to None: the preset supplies the
value and an explicit option overrides it.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping
from typing import Any, TypeVar

import click

from svgf_cli.errors import UsageError
from svgf_cli.filters.params import PRESETS, SVGFParams, resolve_params

F = TypeVar("F", bound=Callable[..., Any])

_CLICK_TYPES: dict[str, click.ParamType] = {"float": click.FLOAT, "int": click.INT}


def param_fields() -> list[dataclasses.Field[Any]]:
    """The SVGFParams fields, in declaration order."""
    return list(dataclasses.fields(SVGFParams))


def option_name(field_name: str) -> str:
    """``moments_alpha`` -> ``--moments-alpha``."""
    return "--" + field_name.replace("_", "-")


def _field_type_name(f: dataclasses.Field[Any]) -> str:
    # `from __future__ import annotations` in params.py makes types strings; accept both.
    return f.type if isinstance(f.type, str) else f.type.__name__


def _param_option(f: dataclasses.Field[Any]) -> Callable[[F], F]:
    help_text = f.metadata.get("help", "")
    defaults = ", ".join(f"{name}: {getattr(p, f.name)}" for name, p in PRESETS.items())
    help_text = f"{help_text} [{defaults}]"
    type_name = _field_type_name(f)
    flag = option_name(f.name)
    if type_name == "bool":
        negative = "--no-" + f.name.replace("_", "-")
        return click.option(f"{flag}/{negative}", f.name, default=None, help=help_text)
    click_type = _CLICK_TYPES.get(type_name)
    if click_type is None:
        raise TypeError(f"SVGFParams.{f.name}: unsupported type {type_name}")
    return click.option(
        flag, f.name, type=click_type, default=None, metavar=type_name.upper(), help=help_text
    )


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
        default="paper",
        show_default=True,
        help="Parameter preset; any parameter option overrides its value.",
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
    """Refuse values that would make the filter meaningless, naming the option."""
    problems: list[str] = []

    def need(ok: bool, field_name: str, what: str) -> None:
        if not ok:
            problems.append(f"{option_name(field_name)} {getattr(params, field_name)}: {what}")

    need(0.0 < params.alpha <= 1.0, "alpha", "must be in (0, 1]")
    need(0.0 < params.moments_alpha <= 1.0, "moments_alpha", "must be in (0, 1]")
    need(params.history_cap >= 1, "history_cap", "must be at least 1")
    need(params.atrous_iterations >= 0, "atrous_iterations", "must be >= 0")
    need(
        -1 <= params.feedback_iteration < max(params.atrous_iterations, 1),
        "feedback_iteration",
        "must be -1 or an iteration index below --atrous-iterations",
    )
    need(params.sigma_luminance > 0, "sigma_luminance", "must be > 0")
    need(params.sigma_normal >= 0, "sigma_normal", "must be >= 0")
    need(params.sigma_depth > 0, "sigma_depth", "must be > 0")
    need(params.albedo_epsilon > 0, "albedo_epsilon", "must be > 0")
    need(params.firefly_clamp >= 0, "firefly_clamp", "must be >= 0 (0 = off)")
    need(params.history_clamp >= 0, "history_clamp", "must be >= 0 (0 = off)")
    need(0.0 < params.taa_alpha <= 1.0, "taa_alpha", "must be in (0, 1]")
    if problems:
        raise UsageError("; ".join(problems))


def describe_params(params: SVGFParams) -> str:
    """One line of every resolved parameter, for the start-up log."""
    return " ".join(f"{f.name}={getattr(params, f.name)}" for f in param_fields())
