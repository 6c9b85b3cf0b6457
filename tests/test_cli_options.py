"""Bad option values are usage errors: one line on stderr, exit status 2, no traceback.

Covers the QA findings R3, R4, R5, R8, R9, R10 and R11 (option part): seeds,
non-finite floats, size caps, ``--scale``, tiny ``--tau``, ``budget``/``design``
``--fs``, ``table --satellite``/``--columns``, ``--alpha`` and ``budget --mask``.  Valid
values still work.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from click.testing import CliRunner

from accal.cli import main
from accal.errors import ValidationError

SAMPLES = Path(__file__).resolve().parents[1] / "data" / "samples"
GRACE_A = SAMPLES / "ACC1B_2003-09-14_A_00.asc"


def invoke(*args: object) -> tuple[int, str, str, BaseException | None]:
    res = CliRunner().invoke(main, [str(a) for a in args])
    exc = None if isinstance(res.exception, SystemExit) else res.exception
    return res.exit_code, res.stdout, res.stderr, exc


def usage_error(*args: object) -> str:
    """Run a command that must fail with a one-line usage error; return that line."""
    code, _, err, exc = invoke(*args)
    assert exc is None, repr(exc)
    assert "Traceback" not in err
    assert code == 2, err
    lines = err.splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("accal: "), err
    return lines[0]


@pytest.fixture(scope="module")
def run_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A small simulated rotating-platform run (0.1 day at 1 Hz)."""
    path = tmp_path_factory.mktemp("run") / "run.parquet"
    code, _, err, _ = invoke("simulate", "gap", "--days", "0.1", "--out", path)
    assert code == 0, err
    return path


@pytest.fixture(scope="module")
def grace_out(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """An accal grace-bias output directory (GRACE-A, 2003-09-14, parquet)."""
    out = tmp_path_factory.mktemp("gb") / "out"
    code, _, err, _ = invoke("grace-bias", GRACE_A, "--out", out, "-q")
    assert code == 0, err
    return out


# --- simulate grace / simulate gap (R3, R8) ------------------------------------------


@pytest.mark.parametrize(
    ("args", "option", "says"),
    [
        (["--seed", "-1"], "--seed", ">= 0, got -1"),
        (["--duration", "1e12"], "--duration", "(0, 1e6] s"),
        (["--duration", "nan"], "--duration", "got nan"),
        (["--duration", "inf"], "--duration", "got inf"),
        (["--gaps", "-1"], "--gaps", "[0, 1e6]"),
        (["--flagged", "nan"], "--flagged", "[0, 1)"),
        (["--noise", "inf"], "--noise", ">= 0"),
    ],
)
def test_simulate_grace_bad_values(tmp_path, args, option, says):
    line = usage_error("simulate", "grace", "--duration", "600", *args, "--out", tmp_path / "a.asc")
    assert option in line and says in line
    assert not any(tmp_path.iterdir())


@pytest.mark.parametrize(
    ("args", "option", "says"),
    [
        (["--seed", "-5"], "--seed", ">= 0, got -5"),
        (["--days", "nan"], "--days", "> 0 days, got nan"),
        (["--days", "inf"], "--days", "got inf"),
        (["--days", "-1"], "--days", "> 0 days"),
        (["--days", "1e9"], "--days", "at most 1e8"),
        (["--fs", "1e9"], "--fs", "at most 50000"),
        (["--fs", "nan"], "--fs", "> 0 Hz, got nan"),
        (["--fs", "0"], "--fs", "> 0 Hz"),
        (["--tau", "inf"], "--tau", "got inf"),
        (["--signal-period", "0"], "--signal-period", "> 0 s, got 0 s"),
        (["--signal-period", "-86400"], "--signal-period", "> 0 s"),
        (["--signal-period", "nan"], "--signal-period", "got nan"),
        (["--signal-amplitude", "nan"], "--signal-amplitude", "finite number, got nan"),
        (["--quadratic", "nan"], "--quadratic", "finite number, got nan"),
        (["--temperature-coupling", "inf"], "--temperature-coupling", "finite number, got inf"),
        (["--temperature-coupling", "-inf"], "--temperature-coupling", "got -inf"),
    ],
)
def test_simulate_gap_bad_values(tmp_path, args, option, says):
    line = usage_error("simulate", "gap", "--days", "0.01", *args, "--out", tmp_path / "r.parquet")
    assert option in line and says in line
    assert not any(tmp_path.iterdir())


def test_simulate_valid_values_still_work(tmp_path):
    code, _, err, _ = invoke(
        "simulate", "gap", "--days", "0.01", "--seed", "3", "--signal-amplitude", "1e-8",
        "--signal-period", "3600", "--quadratic", "0.1", "--out", tmp_path / "r.parquet",
    )  # fmt: skip
    assert code == 0, err
    import pandas as pd

    assert np.isfinite(pd.read_parquet(tmp_path / "r.parquet")["m_y"]).all()
    code, _, err, _ = invoke(
        "simulate", "grace", "--seed", "0", "--duration", "600", "--out", tmp_path / "g.asc"
    )
    assert code == 0, err


def test_simulate_gap_library_checks():
    from accal.simulate.gap import simulate_gap

    for kwargs, says in (
        ({"days": float("nan")}, "days"),
        ({"seed": -1}, "seed"),
        ({"signal_period": 0.0}, "signal_period"),
        ({"quadratic": float("inf")}, "quadratic"),
    ):
        with pytest.raises(ValidationError, match=says):
            simulate_gap(**{"days": 0.01, **kwargs})


def test_simulate_gap_blocks_are_bounded(monkeypatch):
    """Blocks hold at most MAX_BLOCK_SAMPLES samples; 1 Hz blocks are unchanged."""
    from accal.simulate import gap

    assert gap.MAX_BLOCK_SAMPLES >= 10 * 86400 * 10  # 10-day blocks up to 10 Hz as before
    blocks = gap.simulate_gap_chunks(0.05, 600, 200, 1.0, chunk_days=10.0, noise=False)
    assert [b[0]["time"].size for b in blocks] == [4200]  # 7 whole periods, one block
    monkeypatch.setattr(gap, "MAX_BLOCK_SAMPLES", 1300)
    blocks = gap.simulate_gap_chunks(0.05, 600, 200, 1.0, chunk_days=10.0, noise=False)
    assert [b[0]["time"].size for b in blocks] == [1200, 1200, 1200, 600]
    # simulate_gap (one block, chunk_days = inf) is not split
    data, truth = gap.simulate_gap(0.05, noise=False)
    assert len(data) == 4200 and len(truth) == 7


# --- budget / design (R3, R9, R11) ---------------------------------------------------


@pytest.mark.parametrize(
    ("args", "option", "says"),
    [
        (["--tau", "600", "--fs", "nan"], "--fs", "> 0 Hz, got nan"),
        (["--tau", "600", "--fs", "0"], "--fs", "> 0 Hz, got 0 Hz"),
        (["--tau", "600", "--fs", "-1"], "--fs", "> 0 Hz"),
        (["--tau", "600", "--fs", "1e9"], "--tau", "at most 50000"),
        (["--tau", "600", "--integration", "nan"], "--integration", "got nan"),
        (["--tau", "600", "--integration", "0"], "--integration", "> 0 s, got 0 s"),
        (["--tau", "600", "--integration", "6e8"], "--integration", "at most 1000000"),
        (["--tau", "600", "--method", "gls", "--integration", "864000"], "--integration", "gls"),
        (["--tau", "nan"], "--tau", "got nan"),
        (["--tau", "100"], "--tau", "> 200 s"),
        (["--taus", "300:310:1e-9"], "--taus", "at most 10000"),
        (["--taus", "300:inf:1"], "--taus", "finite"),
        (["--taus", "300:310"], "--taus", "START:STOP:STEP"),
    ],
)
def test_budget_bad_values(args, option, says):
    line = usage_error("budget", "--mask", "200", *args)
    assert option in line and says in line


@pytest.mark.parametrize("mask", ["-1", "0", "nan", "inf"])
def test_budget_bad_mask_is_a_usage_error(mask):
    line = usage_error("budget", "--mask", mask, "--tau", "600")
    assert "--mask" in line and "> 0 s" in line


def test_budget_valid_values_still_work():
    code, stdout, err, _ = invoke("budget", "--mask", "200", "--tau", "600", "--integration", "0.5")
    assert code == 0, err
    assert "sigma over T = 0.5 s (1 period of 600 s = 600 s, the whole periods nearest T)" in stdout
    code, stdout, err, _ = invoke("budget", "--mask", "200", "--taus", "400:1000:200", "--json")
    assert code == 0, err


@pytest.mark.parametrize(
    ("args", "option", "says"),
    [
        (["--periods", "100000000"], "--periods", "at most 10000000"),
        (["--fs", "0"], "--fs", "> 0 Hz, got 0 Hz"),
        (["--fs", "inf"], "--fs", "got inf"),
        (["--fs", "1e9"], "--tau", "at most 50000"),
        (["--mask", "nan"], "--mask", "(0, 600) s"),
        (["--mask", "201"], "tm·fs divisible by 4", ""),
    ],
)
def test_design_bad_values(tmp_path, args, option, says):
    base = {"--tau": "600", "--mask": "200"}
    for k, v in zip(args[::2], args[1::2], strict=True):
        base[k] = v
    flat = [x for kv in base.items() for x in kv]
    line = usage_error("design", *flat, "--out", tmp_path / "p.csv")
    assert option in line and says in line
    assert not any(tmp_path.iterdir())


def test_design_valid_values_still_work(tmp_path):
    code, _, err, _ = invoke(
        "design", "--tau", "600", "--mask", "200", "--periods", "2", "--out", tmp_path / "p.csv"
    )
    assert code == 0 and "1200 samples" in err


# --- demod --tau below one sample (R5) -----------------------------------------------


@pytest.mark.parametrize("tau", ["1e-10", "1e-7", "0.5", "0.9"])
def test_demod_tau_below_one_sample(run_file, tmp_path, tau):
    out = tmp_path / "o"
    line = usage_error("demod", run_file, "--tau", tau, "--mask", "0", "--out", out)
    assert f"--tau {tau} s is shorter than one sample" in line
    assert "at least 1 s" in line and "internal error" not in line and "0 s or" not in line
    assert not out.exists()


def test_demod_tau_below_one_sample_of_one_run_fails_that_run_only(run_file, tmp_path):
    """QA: one run sampled every 1000 s beside a 1 Hz run stopped the batch (exit 2)."""
    from accal.io.writers import write_table

    rows = pd.read_parquet(run_file)
    coarse = tmp_path / "coarse.parquet"
    write_table(rows.assign(time=rows["time"] * 1000.0), coarse, units={"theta": "rad"})
    out = tmp_path / "o"
    code, _, err, _ = invoke(
        "demod", run_file, coarse, "--tau", "600", "--mask", "200", "--out", out
    )
    assert code == 1
    (line,) = [x for x in err.splitlines() if "coarse.parquet" in x]
    assert "tau = 600 s is shorter than one sample (fs = 0.001 Hz)" in line
    assert (out / "periods.parquet").exists()  # the good run is processed
    assert set(pd.read_parquet(out / "periods.parquet")["source"]) == {run_file.name}


def test_demod_valid_tau_still_works(run_file, tmp_path):
    code, _, err, _ = invoke(
        "demod", run_file, "--tau", "600", "--mask", "200", "--out", tmp_path / "o", "-q"
    )
    assert code == 0, err
    # a whole number of samples that the pattern does not fit: still the run's own message
    code, _, err, _ = invoke(
        "demod", run_file, "--tau", "1.5", "--mask", "0", "--out", tmp_path / "p", "-q"
    )
    assert code == 1 and "use tau = 1 s or 2 s" in err


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="/proc")
def test_demod_tau_check_leaves_the_workers_forked(run_file, tmp_path):
    """The τ check reads a chunk of a Parquet run in the batch process; pyarrow's
    thread pool, started by that read, made every demod batch start its workers
    from a fork server (~0.4 s more per batch)."""
    import shutil
    import subprocess

    second = tmp_path / "second.parquet"
    shutil.copy(run_file, second)
    env = {k: v for k, v in os.environ.items() if k != "ACCAL_START_METHOD"}
    out = tmp_path / "o"
    cmd = [sys.executable, "-m", "accal", "demod", str(run_file), str(second)]
    cmd += ["--tau", "600", "--mask", "200", "--out", str(out), "-j", "2", "-q"]
    subprocess.run(cmd, check=True, env=env, capture_output=True)
    (start,) = [x for x in (out / "accal.log").read_text().splitlines() if "inputs run in" in x]
    assert start.endswith("2 worker processes (fork)"), start


# --- grace-bias: --scale, --alpha, --format (R4, R11) ------------------------------


@pytest.mark.parametrize("scale", ["inf", "1e400,1,1", "1,-inf,1", "1,1,nan", "0"])
def test_scale_non_finite_or_non_positive_is_refused(tmp_path, scale):
    code, _, err, exc = invoke("grace-bias", GRACE_A, "--scale", scale, "--out", tmp_path / "o")
    assert exc is None and "Traceback" not in err
    assert code == 2, err
    assert err.splitlines() == [
        f"accal: --scale expects 'tn02', one positive finite number or three 'sx,sy,sz', "
        f"got {scale!r} (see 'accal grace-bias --help')"
    ]
    assert not (tmp_path / "o").exists()


def test_parse_scale():
    from accal.calibration import parse_scale

    assert parse_scale("2", "GRACE-A") == (2.0, 2.0, 2.0)
    assert parse_scale("1e300,1,1", "GRACE-A") == (1e300, 1.0, 1.0)
    for bad in ("inf", "1e400", "-1", "nan,1,1"):
        with pytest.raises(ValidationError, match="positive finite"):
            parse_scale(bad, "GRACE-A")


@pytest.mark.parametrize("alpha", ["nan", "inf", "-inf", "0", "1", "2"])
def test_alpha_must_be_in_0_1(tmp_path, alpha):
    line = usage_error("grace-bias", GRACE_A, "--alpha", alpha, "--out", tmp_path / "o", "-q")
    assert line == f"accal: --alpha must be a number in (0, 1), got {alpha}"


def test_alpha_nan_refused_by_demod_and_diagnose(run_file, tmp_path):
    line = usage_error(
        "demod", run_file, "--tau", "600", "--mask", "200", "--alpha", "nan", "--out", tmp_path
    )
    assert "--alpha" in line
    assert "--alpha" in usage_error("diagnose", tmp_path, "--alpha", "nan")


# --- table (R10) ---------------------------------------------------------------------


@pytest.mark.parametrize("sat", ["Q", "GRACE-Q", "GRACE-B", "C"])
def test_table_unknown_satellite(grace_out, tmp_path, sat):
    line = usage_error("table", grace_out, "--satellite", sat)
    assert line == (
        f"accal: --satellite {sat!r} is not in {grace_out / 'bias_drift.parquet'} "
        "(it holds GRACE-A)"
    )
    usage_error("table", grace_out, "--satellite", sat, "--export", tmp_path / "q.csv")
    assert not (tmp_path / "q.csv").exists()


def test_table_known_satellite_outside_the_dates_has_no_rows(grace_out):
    for sat in ("A", "grace-a", "GRACE-A"):
        code, stdout, err, _ = invoke("table", grace_out, "--satellite", sat)
        assert code == 0, err
        assert len(stdout.strip().splitlines()) == 1 + 3
    code, stdout, err, _ = invoke("table", grace_out, "--satellite", "A", "--start", "2010-01-01")
    assert code == 0 and stdout.strip() == "(no rows)", err


@pytest.mark.parametrize("cols", [",,,", " , ", ","])
def test_table_empty_column_list(grace_out, tmp_path, cols):
    line = usage_error("table", grace_out, "--columns", cols)
    assert line.startswith(f"accal: --columns names no column, got {cols!r}")
    assert "source, satellite, date" in line
    usage_error("table", grace_out, "--columns", cols, "--export", tmp_path / "y.csv")
    assert not (tmp_path / "y.csv").exists()


def test_table_valid_columns_still_work(grace_out):
    code, stdout, err, _ = invoke("table", grace_out, "--columns", "axis, bias,")
    assert code == 0, err
    assert stdout.split()[:2] == ["axis", "bias"]


def test_column_names_the_time_column(tmp_path):
    """``--column time=t`` reads a table timed by a column ``t``; ``--column when=t``
    is a usage error naming the keys."""
    t = np.arange(0.0, 4000.0)
    rng = np.random.default_rng(3)
    table = pd.DataFrame({"t": t, "lin_accl_x": 1e-7 + 1e-9 * rng.standard_normal(t.size)})
    path = tmp_path / "run.csv"
    table.to_csv(path, index=False)
    code, _, err, exc = invoke("grace-bias", path, "--column", "time=t", "--out", tmp_path / "o")
    assert code == 0 and exc is None, err
    assert (tmp_path / "o" / "bias_drift.parquet").exists()
    line = usage_error("grace-bias", path, "--column", "when=t", "--out", tmp_path / "p")
    assert "x|y|z|time" in line
