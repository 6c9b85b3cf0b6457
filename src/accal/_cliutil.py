"""Helpers shared by the click commands (config files, error lines, progress bars)."""

from __future__ import annotations

import datetime as dt
import math
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import click

from accal._runtime import keep_signals_in_python

#: Context settings of the ``accal`` group and of the commands built on their own.
CONTEXT_SETTINGS: dict[str, Any] = {"help_option_names": ["-h", "--help"], "max_content_width": 100}


class OutPath(click.Path):
    """A ``click.Path`` that refuses an empty or blank value.

    ``Path("")`` is the current directory: an unset variable in a cron line
    (``--out "$OUT"``) wrote a run's outputs there (issue 23).
    """

    def convert(self, value: Any, param: click.Parameter | None, ctx: click.Context | None) -> Any:
        if isinstance(value, str) and not value.strip():
            self.fail("empty path (an unset variable?)", param, ctx)
        return super().convert(value, param, ctx)


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

    A usage error of a command (a bad option value, a missing argument) is one
    line, ``accal: what is wrong (see 'accal CMD --help')``, exit status 2, instead
    of Click's four-line block.  An :class:`OSError` that escapes a command (an output path under a file, a
    read-only or full disk, ...) is reported as ``accal: PATH: what the system
    said`` with exit status 2 instead of a traceback (``accal --debug`` keeps the
    traceback).  A :class:`MemoryError` (a problem size the option checks let
    through but the machine cannot hold) is ``accal: out of memory (...)``, exit
    status 1.
    """

    def list_commands(self, ctx: click.Context) -> list[str]:
        """The commands in the order they were registered (workflow order, not A-Z)."""
        return list(self.commands)

    def invoke(self, ctx: click.Context) -> Any:
        import os

        try:
            if ctx.invoked_subcommand:
                keep_signals_in_python()
            return super().invoke(ctx)
        except click.UsageError as exc:  # an option value, a missing argument: one line
            if os.environ.get("ACCAL_DEBUG"):
                raise
            err(f"{_usage_message(exc)} (see '{_command_path(exc, ctx)} --help')")
            sys.exit(exc.exit_code)
        except KeyboardInterrupt:  # Ctrl-C or SIGTERM (accal.__main__) in any command
            # one line and 130, as grace-bias's batch says it (issue 23: accal demod printed
            # Click's "Aborted!" with status 1); files being written were removed by
            # accal.io.writers.atomic_path on the way out
            err("interrupted")
            sys.exit(130)
        except BrokenPipeError:  # `accal budget ... | head -1`: the reader is gone
            # quiet, like other Unix tools (status 128 + SIGPIPE); stdout to /dev/null so
            # that the interpreter's final flush does not fail again (Python docs, signal)
            devnull = os.open(os.devnull, os.O_WRONLY)
            os.dup2(devnull, sys.stdout.fileno())
            sys.exit(141)
        except OSError as exc:
            if os.environ.get("ACCAL_DEBUG"):
                raise
            where = exc.filename or "accal"
            err(f"{where}: {exc.strerror or exc}")
            sys.exit(2)
        except MemoryError as exc:  # a size the option checks let through, on a small machine
            if os.environ.get("ACCAL_DEBUG"):
                raise
            err(f"out of memory ({exc or 'MemoryError'}); use smaller option values")
            sys.exit(1)


def _usage_message(exc: click.UsageError) -> str:
    """The message of a usage error; Click's "Invalid value for '--x': " prefix is
    dropped when the message already names the option."""
    if isinstance(exc, click.BadParameter) and exc.param is not None:
        names = [*getattr(exc.param, "opts", []), *getattr(exc.param, "secondary_opts", [])]
        if any(n in exc.message for n in names):
            return exc.message
    return exc.format_message()


def _command_path(exc: click.UsageError, ctx: click.Context) -> str:
    """``accal SUBCOMMAND`` of the failed command, whatever the program was called."""
    c: click.Context | None = exc.ctx or ctx
    parts: list[str] = []
    while c is not None and c.parent is not None:
        parts.insert(0, c.info_name or "")
        c = c.parent
    return " ".join(["accal", *parts])


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


def check_files(**named: Path | None) -> None:
    """Usage error (exit 2) for a file an option names that is not there.

    ``named``: option name → path (None: not given).  QA (issue 23): a missing
    ``--reference``/``--aux`` failed every input with exit 1, as if the inputs were bad.
    """
    for option, path in named.items():
        if path is None:
            continue
        if not Path(path).exists():
            usage_fail(f"{path}: no such file (--{option.replace('_', '-')})")
        if Path(path).is_dir():
            usage_fail(f"{path}: a directory, not a file (--{option.replace('_', '-')})")


def is_date(text: str) -> bool:
    """True for a calendar day written ``YYYY-MM-DD`` (ten characters, a real date).

    Parameters
    ----------
    text : str
        The option value.

    Returns
    -------
    bool
        Whether ``text`` is an ISO day such as ``2005-01-31``.
    """
    try:
        dt.date.fromisoformat(text)
    except ValueError:
        return False
    return len(text) == 10


def fmt_number(value: float) -> str:
    """A number as the messages show it (``nan``, ``inf``, ``0.5``, ``1e12``, ``1e-9``)."""
    return f"{value:g}".replace("e+0", "e").replace("e+", "e").replace("e-0", "e-")


def _bounds(
    low: float | None, high: float | None, low_open: bool, high_open: bool, unit: str
) -> str:
    """``> 0 s``, ``>= 0``, ``in (0, 1)``, ``<= 10 Hz`` or ``""`` (no bound)."""
    if low is not None and high is not None:
        return f"in {'(' if low_open else '['}{fmt_number(low)}, {fmt_number(high)}{')' if high_open else ']'}{unit}"
    if low is not None:
        return f"{'>' if low_open else '>='} {fmt_number(low)}{unit}"
    if high is not None:
        return f"{'<' if high_open else '<='} {fmt_number(high)}{unit}"
    return ""


def check_number(
    option: str,
    value: float | None,
    *,
    low: float | None = None,
    high: float | None = None,
    low_open: bool = False,
    high_open: bool = False,
    unit: str = "",
    what: str = "",
    why: str = "",
) -> None:
    """Usage error (one line, exit status 2) unless ``value`` is finite and within bounds.

    Parameters
    ----------
    option : str
        The option as the user typed it (``"--fs"``).
    value : float or None
        Its value; None (option not given) passes.
    low, high : float, optional
        Bounds.
    low_open, high_open : bool
        Exclude the bound itself.
    unit : str
        Unit shown after the numbers (``" s"``, ``" Hz"``).
    what : str
        What the option is, shown after its name (``"masking time TM"``).
    why : str
        Reason for a bound, shown after it (``"at most 1e6 samples of 1 s"``).

    Examples
    --------
    ``check_number("--fs", nan, low=0, low_open=True, unit=" Hz")`` exits with
    ``accal: --fs must be a finite number > 0 Hz, got nan``; NaN and inf never pass.
    """
    if value is None:
        return
    ok = math.isfinite(value)
    if ok and low is not None:
        ok = value > low if low_open else value >= low
    if ok and high is not None:
        ok = value < high if high_open else value <= high
    if not ok:
        name = f"{option} ({what})" if what else option
        rng = _bounds(low, high, low_open, high_open, unit)
        shown = str(value) if isinstance(value, int) else fmt_number(value)
        shown += unit if math.isfinite(value) else ""
        kind = "a number" if low is not None and high is not None else "a finite number"
        rng = f" {rng}" if rng else ""
        rng += f" ({why})" if why else ""
        usage_fail(f"{name} must be {kind}{rng}, got {shown}")


def check_seed(option: str, seed: int | None) -> None:
    """Usage error (one line, exit status 2) unless ``seed`` is None or an integer >= 0.

    NumPy's generators take any non-negative integer (arbitrarily large) as a seed.
    """
    if seed is not None and seed < 0:
        usage_fail(f"{option} must be a whole number >= 0, got {seed}")


def check_size(option: str, n: float, cap: float, what: str) -> None:
    """Usage error (one line, exit status 2) when a problem size ``n`` exceeds ``cap``.

    Parameters
    ----------
    option : str
        The option(s) that set the size, as typed (``"--days/--fs"``).
    n : float
        The size the options ask for (``what`` counts it).
    cap : float
        The largest size allowed.
    what : str
        What ``n`` counts, plural (``"samples"``, ``"tau values"``).
    """
    if not n <= cap:
        usage_fail(
            f"{option}: {fmt_number(float(n))} {what} asked for; at most {fmt_number(float(cap))} allowed"
        )


def _check_alpha(ctx: click.Context, param: click.Parameter, value: float | None) -> Any:
    """``--alpha`` callback: a probability in (0, 1); NaN and inf are refused too."""
    check_number("--alpha", value, low=0, high=1, low_open=True, high_open=True)
    return value


def alpha_option(f: Any) -> Any:
    """``--alpha``: false-detection probability per closure selection step (shared)."""
    return click.option(
        "--alpha",
        type=float,
        default=0.01,
        show_default=True,
        callback=_check_alpha,
        help="False-detection probability per --close-loop selection step, in (0, 1).",
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


def plots_option(f: Any) -> Any:
    """``--plots``: write the closure's PNG plots (off by default: cost on an archive)."""
    return click.option(
        "--plots",
        is_flag=True,
        help="With --close-loop: PNG plots of each residual before/after, its spectrum and "
        "the effects found (off by default: on an archive they cost more than the closure).",
    )(f)


def option_stack(options: Sequence[Callable[[Any], Any]]) -> Callable[[Any], Any]:
    """One decorator attaching ``options`` to a command function, listed in that order.

    Parameters
    ----------
    options : sequence of callable
        Option decorators (``click.option(...)``, :func:`config_option`, ...), in
        the order ``--help`` lists them (first = top), as if stacked above the
        function in that order.

    Returns
    -------
    callable
        The decorator (apply it before ``click.command``).
    """

    def decorate(f: Any) -> Any:
        for option in reversed(options):
            f = option(f)
        return f

    return decorate


def format_option(help: str | None = None) -> Callable[[Any], Any]:
    """``--format parquet|csv`` (the value is ``fmt``), shared by grace-bias and demod.

    Parameters
    ----------
    help : str, optional
        Its help text (demod's has none).

    Returns
    -------
    callable
        The option decorator.
    """
    return click.option(
        "--format",
        "fmt",
        type=click.Choice(["parquet", "csv"]),
        default="parquet",
        show_default=True,
        help=help,
    )


def quiet_option(f: Any) -> Any:
    """``--quiet``/``-q``: no progress bar or summary (grace-bias, diagnose)."""
    return click.option("--quiet", "-q", is_flag=True, help="No progress bar or summary.")(f)


def fs_option(f: Any) -> Any:
    """``--fs``: sampling frequency of the rotating-platform commands (design, budget, gap)."""
    return click.option(
        "--fs", type=float, default=1.0, show_default=True, help="Sampling frequency [Hz]."
    )(f)
