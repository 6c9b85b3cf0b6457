"""Issue 23 finding 10: exit codes and messages of the CLI."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest
from click.testing import CliRunner

from accal.cli import main


def _terminal_signals() -> None:
    """In the child: SIGINT/SIGTERM as a terminal gives them.

    An ignored disposition is inherited across exec (a test run started in the
    background ignores SIGINT: the demod then never saw it; tests/test_batch.py's
    _terminal_signals likewise).
    """
    import signal

    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT, signal.SIGTERM})
    signal.signal(signal.SIGINT, signal.SIG_DFL)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)


SAMPLE = Path(__file__).resolve().parents[1] / "data" / "samples" / "ACC1B_2003-09-14_A_00.asc"


def _run(*args):
    res = CliRunner().invoke(main, [str(a) for a in args])
    return res.exit_code, res.output


@pytest.mark.parametrize("option", ["--reference", "--aux", "--truth"])
def test_a_missing_file_named_by_an_option_is_a_usage_error(tmp_path, option):
    missing = tmp_path / "nope.parquet"
    out = tmp_path / "o"
    code, msg = _run("grace-bias", SAMPLE, option, missing, "--out", out)
    assert code == 2 and f"{missing}: no such file ({option})" in msg
    assert not out.exists()  # nothing created for a run that cannot start


def test_column_mapping_on_an_l1b_input_is_said(tmp_path):
    code, msg = _run("grace-bias", SAMPLE, "--column", "x=nonexistent", "--out", tmp_path / "o")
    assert code == 0
    assert (
        "--column x=nonexistent is for table inputs; this grace-l1b file's columns are fixed" in msg
    )


def test_a_closed_pipe_ends_quietly():
    """``accal budget ... | head -1`` printed ``accal: accal: Broken pipe``, exit 2.

    The reader is gone before accal writes (its start-up takes ~1 s), so the write
    meets a pipe without readers, as after ``head -1``."""
    proc = subprocess.Popen(
        [sys.executable, "-m", "accal", "budget", "--tau", "600", "--mask", "200"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
    )
    proc.stdout.close()
    err = proc.stderr.read()
    proc.wait(timeout=120)
    assert err == b"" and proc.returncode == 141


@pytest.mark.parametrize("cmd", [["grace-bias"], ["demod", "--tau", "600", "--mask", "200"]])
def test_a_run_with_nothing_to_read_creates_no_output_directory(tmp_path, cmd):
    """Issue 23: a failed ``accal demod run1.parquet`` left OUT with a lock and a log."""
    out = tmp_path / "o"
    code, msg = _run(*cmd[:1], tmp_path / "missing.parquet", *cmd[1:], "--out", out)
    assert code == 1 and f"{tmp_path / 'missing.parquet'}: no such file" in msg
    assert not out.exists()
    out.mkdir()  # an existing directory (a cron archive) keeps the failure in its log
    code, _ = _run(*cmd[:1], tmp_path / "missing.parquet", *cmd[1:], "--out", out)
    assert code == 1 and "no such file" in (out / "accal.log").read_text()


@pytest.mark.parametrize("cmd", [["grace-bias"], ["demod", "--tau", "600", "--mask", "200"]])
def test_symlink_loops_and_broken_links_are_named_as_such(tmp_path, cmd):
    """Issue 23: a symlink loop read "no such file" (and ``accal demod`` raised a
    traceback resolving it)."""
    (tmp_path / "a").symlink_to(tmp_path / "b")
    (tmp_path / "b").symlink_to(tmp_path / "a")
    (tmp_path / "gone").symlink_to(tmp_path / "nowhere")
    code, msg = _run(cmd[0], tmp_path / "a", tmp_path / "gone", *cmd[1:], "--out", tmp_path / "o")
    assert code == 1
    assert f"{tmp_path / 'a'}: a symbolic link loop" in msg
    assert f"{tmp_path / 'gone'}: a broken symbolic link (its target does not exist)" in msg
    assert "Traceback" not in msg


def test_log_lines_escape_control_characters_of_file_names(tmp_path):
    """Issue 23: accal.log kept raw terminal escapes from file names."""
    bad = tmp_path / "x\x1b[31mred\x1b[0m.asc"
    bad.write_text("not an accelerometer file\n")
    out = tmp_path / "o"
    code, _ = _run("grace-bias", bad, "--out", out, "-q")
    assert code == 1
    log = (out / "accal.log").read_text()
    assert "\x1b" not in log and "x\\x1b[31mred\\x1b[0m.asc" in log


@pytest.mark.parametrize("sig", ["SIGINT", "SIGTERM"])
def test_demod_interrupted_says_so_and_exits_130(tmp_path, sig):
    """Issue 23 finding 5: SIGINT/SIGTERM during ``accal demod`` printed Click's
    ``Aborted!`` (exit 1); now ``accal: interrupted``, exit 130, as grace-bias, and no
    temporary file is left."""
    import signal
    import time

    from tests.indep import platform_run, write_platform_run

    run = write_platform_run(platform_run(3, days=2.0), tmp_path / "run.parquet")
    out = tmp_path / "o"

    proc = subprocess.Popen(
        [sys.executable, "-m", "accal", "demod", str(run), "--tau", "600", "--mask", "200",
         "--close-loop", "--out", str(out), "-q"],
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=_terminal_signals,
    )  # fmt: skip
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline and not (out / "accal.log").exists():
        time.sleep(0.05)  # the run has started (past the imports)
    time.sleep(0.5)
    assert proc.poll() is None, "the run finished before it could be interrupted"
    proc.send_signal(getattr(signal, sig))
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    assert err.strip().splitlines()[-1] == "accal: interrupted" and "Traceback" not in err
    assert not [p for p in out.iterdir() if ".tmp" in p.name]


def test_zero_filled_inputs_fail_at_once(tmp_path):
    """Issue 23 finding 9: a 2 GB sparse ``.asc`` (format forced) or a small ``.gz`` of
    gigabytes of zeros reached 4.3 GB of memory and 30 s before failing."""
    import gzip

    sparse = tmp_path / "ACC1B_2005-01-01_A_02.asc"
    with open(sparse, "wb") as fh:
        fh.truncate(1 << 31)  # sparse: no disk used
    bomb = tmp_path / "ACC1B_2005-01-02_A_02.asc.gz"
    with gzip.open(bomb, "wb", compresslevel=9) as fh:
        for _ in range(8):
            fh.write(bytes(1 << 24))  # 128 MiB of zeros, ~130 kB compressed
    code, msg = _run("grace-bias", sparse, bomb, "--input-format", "grace-l1b",
                     "--out", tmp_path / "o", "-q")  # fmt: skip
    assert code == 1
    assert f"{sparse}: the first 65,536 bytes are NUL" in msg
    assert f"{bomb}: the first 65,536 bytes after gunzip are NUL" in msg


def test_demod_repeated_ctrl_c_still_exits_130(tmp_path):
    """Ctrl-C pressed again while the run is stopping (or one Ctrl-C that pyarrow
    delivers a second time, ``pyarrow.lib.SignalStopHandler``): still one line and
    status 130, never Click's ``Aborted!``, a traceback or a death by SIGINT (status
    -2; 4 of 30 single interrupts of ``accal demod`` before the late signals were
    ignored)."""
    import signal
    import time

    from tests.indep import platform_run, write_platform_run

    run = write_platform_run(platform_run(4, days=2.0), tmp_path / "run.parquet")
    codes = []
    for trial in range(3):
        out = tmp_path / f"o{trial}"
        proc = subprocess.Popen(
            [sys.executable, "-m", "accal", "demod", str(run), "--tau", "600", "--mask", "200",
             "--close-loop", "--out", str(out), "-q"],
            stderr=subprocess.PIPE,
            text=True,
            preexec_fn=_terminal_signals,
        )  # fmt: skip
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and not (out / "accal.log").exists():
            time.sleep(0.05)
        time.sleep(0.3 + 0.4 * trial)
        assert proc.poll() is None, "the run finished before it could be interrupted"
        for _ in range(40):  # a user hammering Ctrl-C: every 5 ms for 0.2 s
            if proc.poll() is not None:
                break
            proc.send_signal(signal.SIGINT)
            time.sleep(0.005)
        _, err = proc.communicate(timeout=60)
        codes.append(proc.returncode)
        assert proc.returncode == 130, err
        assert err.strip().splitlines()[-1] == "accal: interrupted", err
        assert "Traceback" not in err and "Aborted" not in err, err
        assert not [p for p in out.iterdir() if ".tmp" in p.name]
    assert codes == [130, 130, 130]


def test_an_l1b_file_larger_than_its_record_count_is_refused_before_it_is_read(tmp_path):
    """Issue 23 finding 9: memory is bounded by the header's record count.  A real
    header announcing 60 records followed by 70 MB of records (plain, and gzipped:
    ~0.2 MB inflating to 70 MB) is refused from its first MiB, naming the count; the
    same header with its 60 real records is still read; the failed inputs' memory is
    in the summary's peak RSS."""
    import gzip

    from accal.io import read
    from accal.pipeline import GraceBiasOptions, process_one

    text = SAMPLE.read_bytes()
    end = text.index(b"END OF HEADER")
    body = text[text.index(b"\n", end) + 1 :]
    padded = tmp_path / "ACC1B_2003-09-14_A_00.asc"
    with open(padded, "wb") as fh:
        fh.write(text)
        for _ in range((70 << 20) // len(body)):
            fh.write(body)
    bomb = tmp_path / "ACC1B_2003-09-15_A_00.asc.gz"
    bomb.write_bytes(gzip.compress(padded.read_bytes(), compresslevel=9))
    code, msg = _run("grace-bias", padded, bomb, "--out", tmp_path / "o", "-q")
    assert code == 1
    assert f"{padded}: file larger than 67,108,864 bytes (more than its header's 60 records" in msg
    assert f"{bomb}: gzip stream decompresses to more than 67,108,864 bytes" in msg
    assert "60 records can fill" in msg.split(str(bomb))[1]
    assert read(SAMPLE).time.size == 60  # the bound does not touch a right file
    outcome = process_one(padded, tmp_path / "p", GraceBiasOptions())
    assert not outcome.ok and outcome.peak_rss > 0


def test_a_dead_axis_is_refused_not_calibrated(tmp_path):
    """QA (2026-11-30): an all-zero day gave bias 0 ± 0 (an internal error with
    --close-loop), a stuck x axis a bias σ of 1e-22 m/s²; demod an all-zero m_z
    a_Z = 3e-23 ± 2.7e-12 and an all-zero run an internal error."""
    import numpy as np
    import pandas as pd

    n = 4000
    t = 757_382_400.0 + np.arange(n, dtype=float)
    rng = np.random.default_rng(1)
    live = 1e-7 + 1e-10 * rng.standard_normal((n, 3))
    for name, acc in (("stuck", np.c_[np.full(n, 1e-6), live[:, 1:]]), ("zeros", 0 * live)):
        pd.DataFrame({"gps_time": t, **{f"lin_accl_{a}": acc[:, i] for i, a in enumerate("xyz")}}
                     ).to_csv(tmp_path / f"{name}.csv", index=False)  # fmt: skip
    pd.DataFrame({"gps_time": t, **{f"lin_accl_{a}": live[:, i] for i, a in enumerate("xyz")}}
                 ).to_csv(tmp_path / "live.csv", index=False)  # fmt: skip
    out = tmp_path / "o"
    code, msg = _run("grace-bias", tmp_path / "stuck.csv", tmp_path / "zeros.csv",
                     tmp_path / "live.csv", "--close-loop", "--out", out, "-q")  # fmt: skip
    assert code == 1, msg
    assert "stuck.csv: axis x = 1e-06 at every valid sample (4000): a dead or zero-filled" in msg
    assert "zeros.csv: axis x = 0 and y = 0 and z = 0 at every valid sample" in msg
    assert "internal error" not in msg
    assert (out / "live.calibrated.parquet").exists()  # the batch's good input
    assert not (out / "stuck.calibrated.parquet").exists()
    # demod: a run whose m_z is zero-filled
    run = tmp_path / "run.parquet"
    code, msg = _run("simulate", "gap", "--days", "0.1", "--tau", "600", "--mask", "200",
                     "--out", run)  # fmt: skip
    assert code == 0, msg
    df = pd.read_parquet(run)
    df["m_z"] = 0.0
    df.to_parquet(run, index=False)
    code, msg = _run("demod", run, "--tau", "600", "--mask", "200", "--out", tmp_path / "d", "-q")
    assert code == 1 and "m_z = 0 at every valid sample: a dead or zero-filled channel" in msg


def test_a_directory_s_broken_link_and_fifo_are_named_not_skipped(tmp_path):
    """QA (2026-11-30): in a directory or glob input, a broken link and a FIFO under
    day names were skipped without a word (exit 0): days of an archive on a missing
    volume would vanish unnoticed."""
    import shutil

    d = tmp_path / "arch"
    d.mkdir()
    shutil.copy(SAMPLE, d / "ACC1B_2003-09-14_A_00.asc")
    os.mkfifo(d / "ACC1B_2003-09-15_A_00.asc")
    (d / "ACC1B_2003-09-16_A_00.asc").symlink_to(tmp_path / "missing-volume" / "x.asc")
    for given in (d, d / "ACC1B_*"):
        out = tmp_path / f"o{len(str(given))}"
        code, msg = _run("grace-bias", given, "-r", "--out", out, "-q")
        assert code == 1, msg
        assert "ACC1B_2003-09-15_A_00.asc: not a regular file (a FIFO)" in msg
        assert "ACC1B_2003-09-16_A_00.asc: a broken symbolic link" in msg
        assert (out / "ACC1B_2003-09-14_A_00.calibrated.parquet").exists()
