"""Helpers shared by the click commands (config files, error lines, progress bars)."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

import click


def _command_names(ctx: click.Context) -> set[str]:
    """Names of every accal command and sub-command (``grace-bias``, ``gap``, ...)."""
    root = ctx.find_root().command
    names: set[str] = set()
    todo = [root]
    while todo:
        cmd = todo.pop()
        if isinstance(cmd, click.Group):
            names.update(cmd.commands)
            todo.extend(cmd.commands.values())
    return names


def load_config(ctx: click.Context, param: click.Parameter, value: str | None) -> str | None:
    """Eager ``--config`` callback: a TOML file's ``[<command>]`` table becomes the defaults.

    A file whose top level holds only keys (no command tables) applies to the
    command it is given to.  A file with tables for other commands only (e.g.
    ``[table]``) sets nothing for this one.  Keys are the long option names
    (``keep-going`` or ``keep_going``); a list is accepted for an option that
    takes a comma-separated value (``scale = [1.0, 1.0, 1.0]``) and a single
    string for a repeatable option (``include = "*.asc"``).
    """
    if not value:
        return value
    import tomllib

    path = Path(value)
    try:
        with open(path, "rb") as fh:
            data = tomllib.load(fh)
    except (OSError, tomllib.TOMLDecodeError) as exc:
        raise click.BadParameter(f"{path}: {exc}", ctx=ctx, param=param) from None
    name = ctx.info_name or ""
    commands = _command_names(ctx)
    if name in data:
        section = data[name]
    elif any(k in commands and isinstance(v, dict) for k, v in data.items()):
        section = {}  # tables for other commands only
    else:
        section = data
    if not isinstance(section, dict):
        raise click.BadParameter(f"{path}: [{name}] must be a table", ctx=ctx, param=param)
    # config keys are the long option names, with dashes or underscores ("columns"
    # is accepted for the repeatable --column); messages use the dashed names
    known: dict[str, click.Option] = {}
    shown: dict[str, str] = {}
    for p in ctx.command.params:
        if not isinstance(p, click.Option) or p.name == "config":
            continue
        longs = [o[2:] for o in (*p.opts, *p.secondary_opts) if o.startswith("--")]
        for lo in longs:
            known[lo.replace("-", "_")] = p
            shown[lo.replace("-", "_")] = lo
        known.setdefault(str(p.name), p)
    if "column" in known:
        known["columns"] = known["column"]
    defaults = {}
    for key, val in section.items():
        k = key.replace("-", "_")
        opt = known.get(k)
        if opt is None:
            names = sorted({v for v in shown.values() if not v.startswith("fail")})
            raise click.BadParameter(
                f"{path}: unknown key {key!r} for '{name}' (known: {', '.join(names)})",
                ctx=ctx,
                param=param,
            )
        if k == "fail_fast":
            val = not val
        if opt.multiple and isinstance(val, str):
            val = [val]
        elif not opt.multiple and isinstance(val, list) and not opt.is_flag:
            val = ",".join(str(v) for v in val)
        defaults[str(opt.name)] = val
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
    if quiet or sys.stderr is None or not sys.stderr.isatty():  # None: stderr closed (2>&-)
        return None
    from tqdm import tqdm

    # no monitor thread: the bar is updated as each input completes, and a thread in
    # this process would keep the workers from being forked (accal.batch.start_method)
    tqdm.monitor_interval = 0
    return lambda it, total=None: tqdm(it, total=total, desc=desc, unit="file", file=sys.stderr)


def fail(msg: str) -> None:
    """Print the one-line error and exit with status 1."""
    err(msg)
    sys.exit(1)


def usage_fail(msg: str) -> None:
    """Print the one-line error of a bad option value (a file it names) and exit with status 2."""
    err(msg)
    sys.exit(2)


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
        "channels for --close-loop (implied in grace-bias). A coupling c·x enters as given, "
        "so the bias is the one at channel value 0.",
    )(f)
