"""Shared fixtures: the real sample files in data/samples/ (see PROVENANCE.md)."""

import os

# one BLAS thread, as the accal CLI sets for itself (accal._runtime.single_threaded_blas);
# only effective if numpy is not loaded yet (the Makefile exports it too)
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

from pathlib import Path  # noqa: E402

import pytest  # noqa: E402

SAMPLES_DIR = Path(__file__).resolve().parents[1] / "data" / "samples"

SAMPLE_FILES = {
    "grace_a": "ACC1B_2003-09-14_A_00.asc",
    "grace_b": "ACC1B_2003-09-14_B_00.asc",
    "grace_a_bin": "ACC1B_2003-09-14_A_00.dat",
    "grace_b_bin": "ACC1B_2003-09-14_B_00.dat",
    "grace_ahk_a": "AHK1B_2003-09-14_A_00.asc",
    "grace_ahk_b": "AHK1B_2003-09-14_B_00.asc",
    "gracefo_c": "ACT1B_2023-06-01_C_04.txt",
    "gracefo_d": "ACT1B_2023-06-01_D_04.txt",
    "gracefo_rpt_c": "ACT1B_2023-06-01_C_04.rpt",
    "gracefo_rpt_d": "ACT1B_2023-06-01_D_04.rpt",
    "gracefo_ahk_c": "AHK1B_2023-06-01_C_04.txt",
    "gracefo_ahk_d": "AHK1B_2023-06-01_D_04.txt",
    "swarm_a": "SW_A_ACCACAL_20240511_a_cal_x.csv.gz",
}


@pytest.fixture(scope="session")
def samples() -> dict[str, Path]:
    """Map short names to the real sample files (unmodified copies; never write to them)."""
    return {k: SAMPLES_DIR / v for k, v in SAMPLE_FILES.items()}
