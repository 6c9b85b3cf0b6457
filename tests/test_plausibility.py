"""Wild samples (issue 23 finding 7): a damaged value below the readers' 1000 m/s² limit."""

from __future__ import annotations

from pathlib import Path

import pandas as pd
import pytest
from click.testing import CliRunner

from accal.cli import main
from accal.io import read
from accal.plausibility import flag_wild_samples

SAMPLES = Path(__file__).resolve().parents[1] / "data" / "samples"
GRACE_A = SAMPLES / "ACC1B_2003-09-14_A_00.asc"


def _bias(out: Path) -> dict:
    tab = pd.read_csv(out / "bias_drift.csv")
    return dict(zip(tab["axis"], tab["bias"], strict=True))


def test_one_damaged_value_is_flagged_not_fitted(tmp_path):
    lines = GRACE_A.read_text().splitlines(keepends=True)
    i = next(k for k, ln in enumerate(lines) if "END OF HEADER" in ln) + 11
    f = lines[i].split(" ")
    f[4] = "9.990000000000000e+02"  # lin_accl_z of one record: 999 m/s²
    lines[i] = " ".join(f)
    bad = tmp_path / "d" / GRACE_A.name
    bad.parent.mkdir()
    bad.write_text("".join(lines))
    runner = CliRunner()
    for src, out in ((bad, tmp_path / "bad"), (GRACE_A, tmp_path / "clean")):
        res = runner.invoke(main, ["grace-bias", str(src), "--out", str(out), "--format", "csv"])
        assert res.exit_code == 0, res.output
    log = (tmp_path / "bad" / "accal.log").read_text()
    assert "1 sample(s) of z more than 0.001 m/s²" in log and "flagged invalid" in log
    got, clean = _bias(tmp_path / "bad"), _bias(tmp_path / "clean")
    # was 0.416 m/s²; now the clean day's value to a few 1e-12 (one record fewer)
    assert got["z"] == pytest.approx(clean["z"], abs=1e-10)
    cal = pd.read_csv(tmp_path / "bad" / f"{GRACE_A.stem}.calibrated.csv")
    assert (~cal["valid"]).sum() == 1


@pytest.mark.parametrize(
    "name",
    [
        "ACC1B_2003-09-14_A_00.asc",
        "ACC1B_2003-09-14_B_00.asc",
        "ACT1B_2023-06-01_C_04.txt",
        "ACT1B_2023-06-01_D_04.txt",
    ],
)
def test_real_days_have_no_wild_samples(name):
    series = read(SAMPLES / name)
    _, warnings = flag_wild_samples(series)
    assert warnings == []


def test_the_real_swarm_storm_day_has_no_wild_samples():
    series = read(SAMPLES / "SW_A_ACCACAL_20240511_a_cal_x.csv.gz", columns={"x": "a_cal_x"})
    _, warnings = flag_wild_samples(series)
    assert warnings == []
