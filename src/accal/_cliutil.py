"""Helpers shared by the click commands (config files, error lines, progress bars)."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

import click


def load_config(ctx: click.Context, param: click.Parameter, value: str | None) -> str | None:
    """Eager ``--config`` callback: a TOML file's ``[<command>]`` table becomes the defaults."""
    if not value:
        return value
    import tomllib

    path = Path(value)
    try:
        with open(path, "rb") as fh:
            data = tomllib.load(fh)
    except (OSError, tomllib.TOMLDecodeError) as exc:
        raise click.BadParameter(f"{path}: {exc}", ctx=ctx, param=param) from None
    section = data.get(ctx.info_name, data)
    if not isinstance(section, dict):
        raise click.BadParameter(f"{path}: [{ctx.info_name}] must be a table", ctx=ctx, param=param)
    # config keys are the long option names ("format", "keep-going"), or the
    # parameter names; "columns" is accepted for the repeatable --column
    known: dict[str, str] = {}
    for p in ctx.command.params:
        if not isinstance(p, click.Option) or p.name == "config":
            continue
        known[p.name] = p.name
        for opt in (*p.opts, *p.secondary_opts):
            if opt.startswith("--"):
                known[opt[2:].replace("-", "_")] = p.name
    known["columns"] = known.get("column", "columns")
    defaults = {}
    for key, val in section.items():
        name = known.get(key.replace("-", "_"))
        if name is None:
            raise click.BadParameter(
                f"{path}: unknown key {key!r} for '{ctx.info_name}' "
                f"(known: {', '.join(sorted({k for k in known if not k.startswith('fail')}))})",
                ctx=ctx,
                param=param,
            )
        if key.replace("-", "_") == "fail_fast":
            val = not val
        defaults[name] = val
    ctx.default_map = {**(ctx.default_map or {}), **defaults}
    return value


def config_option(f: Any) -> Any:
    """The ``--config FILE`` option shared by the commands."""
    return click.option(
        "--config",
        type=click.Path(dir_okay=False),
        is_eager=True,
        expose_value=False,
        callback=load_config,
        help="TOML file whose [<command>] table sets option defaults (see configs/).",
    )(f)


def err(msg: str) -> None:
    click.echo(f"accal: {msg}", err=True)


class Group(click.Group):
    """The ``accal`` command group: a file-system error no command handled is one line.

    An :class:`OSError` that escapes a command (an output path under a file, a
    read-only or full disk, ...) is reported as ``accal: PATH: what the system
    said`` with exit status 2 instead of a traceback (``accal --debug`` keeps the
    traceback).
    """

    def invoke(self, ctx: click.Context) -> Any:
        import os

        try:
            return super().invoke(ctx)
        except OSError as exc:
            if os.environ.get("ACCAL_DEBUG"):
                raise
            where = exc.filename or "accal"
            err(f"{where}: {exc.strerror or exc}")
            sys.exit(2)


def progress(quiet: bool, desc: str) -> Any:
    """A ``wrap(iterable, total=None)`` progress bar on a terminal, else None."""
    if quiet or not sys.stderr.isatty():
        return None
    from tqdm import tqdm

    return lambda it, total=None: tqdm(it, total=total, desc=desc, unit="file", file=sys.stderr)


def fail(msg: str) -> None:
    """Print the one-line error and exit with status 1."""
    err(msg)
    sys.exit(1)


def alpha_option(f: Any) -> Any:
    """``--alpha``: false-detection probability per closure selection step (shared)."""
    return click.option(
        "--alpha",
        type=click.FloatRange(min=0, max=1, min_open=True, max_open=True),
        default=0.01,
        show_default=True,
        help="False-detection probability per --close-loop selection step.",
    )(f)


def aux_option(f: Any) -> Any:
    """``--aux FILE``: housekeeping channels offered to the closure (shared)."""
    return click.option(
        "--aux",
        type=click.Path(dir_okay=False, path_type=Path),
        default=None,
        help="Housekeeping (AHK1B or a table with 'time') of the same day(s): candidate "
        "channels for --close-loop (implied in grace-bias).",
    )(f)
