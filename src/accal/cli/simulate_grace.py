"""``accal simulate grace``: a real-like synthetic GRACE/GRACE-FO ACC1B day and its truth.

The options are declared in :mod:`accal.cli.simulate_grace_options`; the files are
written by :func:`accal.simulate.grace.write_simulated_arc`, imported when the
command runs (~0.2 s, not for ``accal --help``).
"""

from __future__ import annotations

import sys
from pathlib import Path

import click

from accal._cliutil import check_number, check_seed, err, fmt_number, is_date, usage_fail
from accal.cli.simulate_grace_options import simulate_grace_options
from accal.errors import AccalError


@click.command(
    "grace",
    short_help="Write a synthetic GRACE/GRACE-FO ACC1B day file and its truth JSON.",
)
@simulate_grace_options
def simulate_grace(
    date: str,
    satellite: str,
    out: Path,
    seed: int | None,
    duration: float,
    gaps: int,
    flagged: float,
    noise: float,
    storm: bool,
    thrusters: bool,
    effects: tuple[str, ...],
    reference_out: Path | None,
    reference_noise: float,
    days: int,
) -> None:
    """Write a real-like synthetic GRACE/GRACE-FO ACC1B day file and its truth JSON.

    All 12 ACC1B columns are filled at the magnitudes of the real files; the truth
    (<out>.truth.json) has the bias, drift and scale, the orbit period, eclipses,
    storm, thruster pulses and every injected effect with its parameters.

    \b
    --effect NAME:key=value,... (times in s, epochs from the start of the day):
      step:axis=x,epoch=43200,size=3e-9
      coupling:axis=y,channel=temperature,coef=3e-9[,lag=600][,tau=300][,tau2=100]
      quadratic:axis=z,coef=1e-18               (m/s^4, about the start)
      scale:axis=x,factor=1.02                  (raw = s*factor*a_true + ...)
      scalematrix:xx=0.98,xy=1e-3,zx=-2e-3      (S of a_ref = S (a_raw - b); others of I)
      splinebias:axis=x,step=21600,amp=1e-9[,seed=0]   (cubic B-spline, nodes k*step GPS s)
      splinebias:axis=x,step=21600,coefs=1e-9;0;-2e-9;...   (nodes t0-step, t0, ...)
      sawtooth:axis=y,period=3000,amp=1e-9[,phase=0]
      growing:axis=y,period=2000,amp0=1e-9,amp1=3e-9[,phase=0]
      exponential:axis=x,amp=3e-9,tau=3000
    A coupling's channel (K) goes to <out>.aux.parquet, for grace-bias --aux.
    --thrusters also writes the pulses as a THR1B file beside <out>
    (THR1B_<date>_<sat>_<rel>.asc/.txt for an ACC1B/ACT1B name), which grace-bias
    finds and uses to leave the firings out.  With --reference-out the truth has
    "reference": "scale" (the 3x3 S that grace-bias --scale fit-matrix should find;
    row i = scale_x, scale_y, scale_z of axis i) and "noise" (model and level).
    """
    from accal.simulate.effects import parse_effect
    from accal.simulate.grace import MAX_SAMPLES, arc_files, write_simulated_arc

    if not is_date(date) or not "1980-01-06" <= date < "2100-01-01":
        raise click.BadParameter(
            f"expected a day YYYY-MM-DD in 1980-01-06 ... 2099-12-31, got {date!r}",
            param_hint="--date",
        )
    check_seed("--seed", seed)
    check_number(
        "--duration",
        duration,
        low=0,
        high=MAX_SAMPLES,  # 1 s sampling
        low_open=True,
        unit=" s",
        why=f"at most {fmt_number(MAX_SAMPLES)} samples of 1 s",
    )
    check_number("--gaps", gaps, low=0, high=MAX_SAMPLES)
    check_number("--flagged", flagged, low=0, high=1, high_open=True, what="fraction")
    check_number("--noise", noise, low=0, unit=" m/s^2/sqrt(Hz)")
    check_number("--reference-noise", reference_noise, low=0, unit=" m/s^2")
    check_number("--days", days, low=1, high=366, what="number of days")
    if days > 1 and date not in out.name:
        usage_fail(
            f"--days {days}: the --out name must contain the date {date} (replaced by each "
            f"day's date), got {out.name!r}"
        )
    parsed = []
    for spec in effects:
        try:
            parsed.append(parse_effect(spec, duration=round(duration) * 1.0))
        except AccalError as exc:
            usage_fail(f"--effect {spec!r}: {exc}")
    try:
        truth_paths = write_simulated_arc(
            out,
            days=days,
            reference_out=reference_out,
            reference_noise=reference_noise,
            date=date,
            satellite=satellite,
            seed=seed,
            duration=duration,
            n_gaps=gaps,
            flagged_fraction=flagged,
            noise=noise,
            storm=storm,
            thrusters=thrusters,
            effects=parsed,
        )
    except AccalError as exc:
        err(str(exc))
        sys.exit(1)
    coupling = any(e.name == "coupling" for e in parsed)
    written = arc_files(
        out,
        date,
        days,
        satellite,
        coupling=coupling,
        thrusters=thrusters,
        reference_out=reference_out,
    )
    truths = ", ".join(str(p) for p in truth_paths)
    click.echo(f"wrote {', '.join(str(p) for p in written)} and {truths}", err=True)
