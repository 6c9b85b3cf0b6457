"""Archive runs: discovery, workers, Dask, manifest/incremental, lock, kill -9, `accal table`."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from click.testing import CliRunner

from accal.batch import OutputLock, discover, group_inputs
from accal.cli import main

SAMPLES = Path(__file__).resolve().parents[1] / "data" / "samples"


def invoke(*args: object) -> tuple[int, str, str]:
    res = CliRunner().invoke(main, [str(a) for a in args], catch_exceptions=False)
    return res.exit_code, res.stdout, res.stderr


@pytest.fixture(scope="module")
def archive(tmp_path_factory) -> Path:
    """Six short simulated days (two satellites, three dates) in a year/month tree."""
    from accal.simulate.grace import write_simulated_grace

    root = tmp_path_factory.mktemp("archive")
    for k, day in enumerate(("2005-01-01", "2005-01-02", "2005-02-01")):
        for sat in "AB":
            sub = root / day[:4] / day[5:7]
            write_simulated_grace(
                sub / f"ACC1B_{day}_{sat}_02.asc",
                date=day,
                satellite=sat,
                seed=10 * k + ord(sat),
                duration=3600.0,
                n_gaps=1,
            )
    (root / "README.txt").write_text("not an accelerometer file\n")
    return root


def read_outputs(out: Path) -> dict[str, object]:
    """Everything a user reads from an output directory (no timestamps)."""
    from accal.pipeline import read_bias_drift

    got: dict[str, object] = {"table": read_bias_drift(out / "bias_drift.parquet")}
    for p in sorted(out.glob("*.calibrated.parquet")):
        got[p.name] = pd.read_parquet(p)
    return got


def assert_same_outputs(a: Path, b: Path) -> None:
    ra, rb = read_outputs(a), read_outputs(b)
    assert ra.keys() == rb.keys()
    for k in ra:
        pd.testing.assert_frame_equal(ra[k], rb[k], check_exact=True)


# ---------------------------------------------------------------- discovery


def test_discover_directories_patterns_and_files(archive, tmp_path):
    files, problems = discover([archive], recursive=True)
    assert [p.name for p in files] == sorted(p.name for p in archive.rglob("ACC1B_*.asc"))
    assert problems == []  # truth JSON files and README are not inputs
    # a pattern, an explicit file given twice, and a pattern that matches nothing
    one = next(archive.rglob("ACC1B_2005-02-01_A_02.asc"))
    files, problems = discover([str(archive / "2005" / "01" / "*_A_*.asc"), one, one, "nope*.asc"])
    assert [p.name for p in files] == [
        "ACC1B_2005-01-01_A_02.asc",
        "ACC1B_2005-01-02_A_02.asc",
        "ACC1B_2005-02-01_A_02.asc",
    ]
    assert problems == [(Path("nope*.asc"), "nope*.asc: no file matches this pattern")]
    # ** patterns recurse
    files, _ = discover([str(archive / "**" / "*_B_02.asc")])
    assert len(files) == 3
    # an empty directory is reported, not silently ignored
    (tmp_path / "empty").mkdir()
    _, problems = discover([tmp_path / "empty"], recursive=True)
    assert problems and "no input file" in problems[0][1]
    # a hard link under another name is the same file: processed once (QA)
    link = tmp_path / "ACC1B_2005-03-01_A_02.asc"
    os.link(one, link)
    files, _ = discover([one, link, tmp_path / "sym.asc"])
    assert files == [one, tmp_path / "sym.asc"]  # a missing file is kept: the reader says so


@pytest.mark.skipif(sys.platform == "win32", reason="POSIX names and FIFOs")
def test_inputs_no_reader_should_open_fail_alone_with_one_line(archive, tmp_path):
    """QA: a file name that is not UTF-8 crashed the whole batch (traceback, nothing
    committed, and so every later cron run); a FIFO hung it for ever with the output
    directory locked.  Each now fails alone, with one line."""
    good = sorted(archive.rglob("ACC1B_2005-01-0*.asc"))
    src = tmp_path / "in"
    src.mkdir()
    bad_name = Path(os.fsdecode(bytes(src) + b"/ACC1B_2005-01-03_A_02\xff.asc"))
    bad_name.write_bytes(good[0].read_bytes())
    fifo = src / "ACC1B_2005-01-04_A_02.asc"
    os.mkfifo(fifo)
    for workers in ("1", "2"):
        out = tmp_path / f"out{workers}"
        code, _, err = invoke("grace-bias", *good, bad_name, fifo, "--out", out, "-j", workers)
        assert code == 1
        lines = [x for x in err.splitlines() if x.startswith("accal: ") and "warning" not in x]
        shown = str(bad_name).encode("utf-8", "backslashreplace").decode()  # as stderr shows it
        assert f"accal: {shown}: file name is not valid UTF-8; rename the file" in lines
        assert f"accal: {fifo}: not a regular file (a FIFO)" in lines
        assert "Traceback" not in err and f"{len(good)} ok" in err and "2 failed" in err
        assert len(read_outputs(out)["table"]) == 3 * len(good)
        assert "\\udcff" in (out / "accal.log").read_text()  # logged, escaped


def test_an_input_replaced_during_the_batch_is_redone_next_run(tmp_path):
    """QA: an input replaced while the batch ran was recorded with the new file's size
    and mtime but the old content's results, so it was 'current' for ever after."""
    from accal.batch import Manifest, file_signature

    p = tmp_path / "in.asc"
    p.write_text("old content\n")
    before = file_signature(p)
    p.write_text("new content, longer\n")  # replaced after it was read
    m = Manifest(tmp_path / "manifest.json")
    m.record(p, {}, [], p.name, before=before)
    assert not m.is_current(p, {})
    m.record(p, {}, [], p.name, before=file_signature(p))  # unchanged while processed
    assert m.is_current(p, {})


def test_groups_by_satellite_and_day(archive):
    files, _ = discover([archive], recursive=True)
    groups = group_inputs([*files, Path("odd_name.parquet")])
    assert [g.key for g in groups] == [
        ("A", "2005-01-01"),
        ("B", "2005-01-01"),
        ("A", "2005-01-02"),
        ("B", "2005-01-02"),
        ("A", "2005-02-01"),
        ("B", "2005-02-01"),
        ("?", "?"),
    ]


def test_directory_without_recursive_is_a_one_line_error(archive, tmp_path):
    code, _, err = invoke("grace-bias", archive, "--out", tmp_path, "-q")
    assert code == 1
    assert (
        err.strip()
        == f"accal: {archive}: is a directory (use --recursive to process the files in it)"
    )


# ---------------------------------------------------------------- parallel runs


def test_workers_and_dask_give_the_serial_outputs(archive, tmp_path):
    distributed = pytest.importorskip("distributed")
    code, _, err = invoke(
        "grace-bias", archive, "-r", "--out", tmp_path / "serial", "-j", "1", "-q"
    )
    assert code == 0, err
    code, _, err = invoke("grace-bias", archive, "-r", "--out", tmp_path / "pool", "-j", "2", "-q")
    assert code == 0, err
    assert_same_outputs(tmp_path / "serial", tmp_path / "pool")
    with distributed.LocalCluster(
        n_workers=2, threads_per_worker=1, processes=False, dashboard_address=None
    ) as cluster:
        code, _, err = invoke(
            "grace-bias", archive, "-r", "--out", tmp_path / "dask", "--scheduler",
            cluster.scheduler_address, "-q",
        )  # fmt: skip
    assert code == 0, err
    assert_same_outputs(tmp_path / "serial", tmp_path / "dask")
    assert len(read_outputs(tmp_path / "dask")["table"]) == 6 * 3


def test_unreachable_scheduler_is_a_clear_error(archive, tmp_path):
    pytest.importorskip("distributed")
    import dask

    with dask.config.set({"distributed.comm.timeouts.connect": "1s"}):
        code, _, err = invoke(
        "grace-bias", next(archive.rglob("*.asc")), "--out", tmp_path, "--scheduler",
            "tcp://127.0.0.1:1", "-q",
        )  # fmt: skip
    assert code == 1
    assert err.startswith("accal: cannot connect to the dask scheduler 'tcp://127.0.0.1:1'")
    assert len(err.strip().splitlines()) == 1


def _closed_port() -> int:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_refused_scheduler_is_said_at_once_without_the_connect_timeout(archive, tmp_path):
    """Nothing listens at the address: the TCP probe says "refused" (the client would
    retry for its 30 s connect timeout, left at its default here); no output written."""
    pytest.importorskip("distributed")
    port = _closed_port()
    out = tmp_path / "o"
    code, _, err = invoke(
        "grace-bias", next(archive.rglob("*.asc")), "--out", out, "--scheduler",
        f"tcp://127.0.0.1:{port}", "-q",
    )  # fmt: skip
    assert code == 1
    assert err.strip() == (
        f"accal: cannot connect to the dask scheduler 'tcp://127.0.0.1:{port}': Connection refused"
    )
    assert not list(out.glob("*.parquet")) and not list(out.glob("*.csv"))


def test_scheduler_probe_leaves_what_it_cannot_judge_to_the_client():
    from accal.batch import _refused

    assert _refused(f"127.0.0.1:{_closed_port()}") == "Connection refused"
    assert "unknown host" in _refused("tcp://no-such-host.invalid:8786")
    for address in ("tls://127.0.0.1:1", "inproc://10.0.0.1/123/1", "scheduler.json", ""):
        assert _refused(address) is None
    import socket

    with socket.socket() as srv:  # something listens: the client takes over
        srv.bind(("127.0.0.1", 0))
        srv.listen()
        assert _refused(f"tcp://127.0.0.1:{srv.getsockname()[1]}") is None


# ---------------------------------------------------------------- incremental


def test_rerun_skips_current_inputs_and_redoes_changed_ones(archive, tmp_path):
    src = tmp_path / "in"
    src.mkdir()
    files = sorted(archive.rglob("ACC1B_*.asc"))
    for p in files[:4]:
        (src / p.name).write_bytes(p.read_bytes())
    out = tmp_path / "out"
    assert invoke("grace-bias", src, "-r", "--out", out, "-q")[0] == 0
    cal = {p.name: p.stat().st_mtime_ns for p in out.glob("*.calibrated.parquet")}
    assert len(cal) == 4

    # nothing changed: everything skipped, nothing rewritten
    code, _, err = invoke("grace-bias", src, "-r", "--out", out)
    assert code == 0
    assert "0 ok, 4 skipped (current), 0 failed" in err
    assert {p.name: p.stat().st_mtime_ns for p in out.glob("*.calibrated.parquet")} == cal

    # one input changed, one new input: only those two are processed
    changed = src / files[0].name
    changed.write_bytes(changed.read_bytes())  # same bytes, new mtime
    os.utime(changed, ns=(time.time_ns(), time.time_ns() + 10**9))
    (src / files[4].name).write_bytes(files[4].read_bytes())
    code, _, err = invoke("grace-bias", src, "-r", "--out", out)
    assert "2 ok, 3 skipped (current)" in err, err
    table = read_outputs(out)["table"]
    assert len(table) == 5 * 3
    assert not table.duplicated(["source", "axis", "method"]).any()

    # --checksum: a touched but identical file is current; switching to --checksum on a
    # directory recorded without checksums adds them (QA: the first touched file after
    # the switch was redone once)
    code, _, err = invoke("grace-bias", src, "-r", "--out", out, "--checksum")
    assert "0 ok, 5 skipped" in err, err
    os.utime(changed, ns=(time.time_ns(), time.time_ns() + 2 * 10**9))
    code, _, err = invoke("grace-bias", src, "-r", "--out", out, "--checksum")
    assert "0 ok, 5 skipped" in err, err
    assert invoke("grace-bias", src, "-r", "--out", out, "--checksum", "--force", "-q")[0] == 0
    os.utime(changed, ns=(time.time_ns(), time.time_ns() + 3 * 10**9))
    code, _, err = invoke("grace-bias", src, "-r", "--out", out, "--checksum")
    assert "0 ok, 5 skipped" in err, err

    # closure settings without --close-loop change nothing: still current
    code, _, err = invoke("grace-bias", src, "-r", "--out", out, "--checksum", "--alpha", "0.05")
    assert "0 ok, 5 skipped" in err, err

    # other options make the outputs out of date; --force redoes all
    code, _, err = invoke("grace-bias", src, "-r", "--out", out, "--order", "2")
    assert "5 ok, 0 skipped" in err, err
    code, _, err = invoke("grace-bias", src, "-r", "--out", out, "--order", "2", "--force")
    assert "5 ok, 0 skipped" in err, err

    # a deleted output makes its input out of date
    next(out.glob("*.calibrated.parquet")).unlink()
    code, _, err = invoke("grace-bias", src, "-r", "--out", out, "--order", "2")
    assert "1 ok, 4 skipped" in err, err

    log = (out / "accal.log").read_text()
    assert log.count(" start accal ") == 11
    assert "skip " in log and "accal grace-bias: 1 ok, 4 skipped" in log


def test_summary_reports_counts_samples_and_throughput(archive, tmp_path):
    bad = tmp_path / "ACC1B_2005-03-01_A_02.asc"
    bad.write_text("garbage\n")
    code, _, err = invoke(
        "grace-bias", *sorted(archive.rglob("ACC1B_2005-01*.asc")), bad, "--out", tmp_path / "o"
    )
    assert code == 1
    summary = err.strip().splitlines()[-1]
    n = sum(
        json.loads(p.read_text())["n_samples"]
        for p in archive.rglob("ACC1B_2005-01*.asc.truth.json")
    )
    assert summary.startswith(
        f"accal grace-bias: 4 ok, 0 skipped (current), 1 failed, 0 not run; {n:,} samples"
    )
    assert "MB/s" in summary and "files/s" in summary


# ---------------------------------------------------------------- lock and crash safety


def test_second_run_on_the_same_directory_refuses(archive, tmp_path):
    with OutputLock(tmp_path, "a test holding the lock"):
        code, _, err = invoke("grace-bias", next(archive.rglob("*.asc")), "--out", tmp_path)
    assert code == 1
    assert "output directory is in use by another accal run" in err
    assert f"pid {os.getpid()}" in err
    assert not list(tmp_path.glob("*.calibrated.*"))
    # released: the next run works
    assert invoke("grace-bias", next(archive.rglob("*.asc")), "--out", tmp_path, "-q")[0] == 0


def _half_days(src: Path, n: int) -> Path:
    """``n`` simulated half days of GRACE-A in ``src`` (long enough to kill a batch mid-way)."""
    from accal.simulate.grace import write_simulated_grace

    for k in range(n):
        write_simulated_grace(
            src / f"ACC1B_2005-01-{k + 1:02d}_A_02.asc",
            date=f"2005-01-{k + 1:02d}",
            satellite="A",
            seed=k,
            duration=43200.0,
        )
    return src


def test_an_input_that_turns_bad_keeps_its_earlier_outputs_and_says_so(archive, tmp_path):
    """QA: a processed day replaced by a damaged copy failed on the re-run (rightly),
    and its earlier calibrated file, report and table rows stayed with nothing saying
    so.  Now a note follows the one-line error, every time until it is processed again."""
    src = tmp_path / "in"
    src.mkdir()
    files = sorted(archive.rglob("ACC1B_*.asc"))[:2]
    for p in files:
        (src / p.name).write_bytes(p.read_bytes())
    out = tmp_path / "out"
    assert invoke("grace-bias", src, "-r", "--out", out, "-q")[0] == 0
    bad = src / files[0].name
    text = bad.read_bytes()
    bad.write_bytes(text[: len(text) // 2] + b"x\n")  # cut mid-record
    for _ in range(2):  # the note stays while the file is bad
        code, _, err = invoke("grace-bias", src, "-r", "--out", out, "-q")
        assert code == 1
        lines = err.strip().splitlines()
        assert len(lines) == 2, err
        assert lines[0].startswith(f"accal: {bad}")
        assert lines[1] == f"accal: {bad}: note: the outputs of an earlier run for it are kept " + (
            "(calibrated file, report, table rows); they are replaced once it is processed again"
        )
        assert len(read_outputs(out)["table"]) == 2 * 3
    assert "FAILED" in (out / "accal.log").read_text()
    # a bad input that was never processed gets the error line only
    new_bad = src / "ACC1B_2005-03-01_A_02.asc"
    new_bad.write_bytes(text[: len(text) // 3])
    code, _, err = invoke("grace-bias", new_bad, "--out", out, "-q")
    assert code == 1 and len(err.strip().splitlines()) == 1, err


def test_kill_minus_nine_then_rerun_gives_the_uninterrupted_outputs(tmp_path):
    """A batch killed with SIGKILL mid-way and re-run ends exactly like a clean run."""
    src = _half_days(tmp_path / "in", 10)
    cmd = [sys.executable, "-m", "accal", "grace-bias", str(src), "-r", "-j", "1", "-q"]
    subprocess.run([*cmd, "--out", str(tmp_path / "clean")], check=True, capture_output=True)

    out = tmp_path / "killed"
    proc = subprocess.Popen(
        [*cmd, "--out", str(out)], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL
    )
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and len(list(out.glob("*.report.json"))) < 3:
        time.sleep(0.02)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    assert proc.returncode == -signal.SIGKILL
    n_done = len(list(out.glob("*.report.json")))
    assert 3 <= n_done < 10, "the batch was not killed mid-way; make the inputs longer"

    res = subprocess.run([*cmd, "--out", str(out)], capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    assert_same_outputs(tmp_path / "clean", out)
    assert not list(out.glob(".*.tmp")), "temporary files left behind"
    manifest = json.loads((out / "manifest.json").read_text())["entries"]
    assert len(manifest) == 10


def _descendants(pid: int) -> set[int]:
    """Live (not zombie) descendants of ``pid``, from ``/proc``."""
    children: dict[int, list[int]] = {}
    for d in Path("/proc").iterdir():
        if d.name.isdigit():
            try:
                stat = (d / "stat").read_text()
            except OSError:
                continue
            fields = stat[stat.rindex(")") + 2 :].split()
            if fields[0] != "Z":
                children.setdefault(int(fields[1]), []).append(int(d.name))
    found, todo = set(), [pid]
    while todo:
        for c in children.get(todo.pop(), []):
            found.add(c)
            todo.append(c)
    return found


def _alive(pid: int) -> bool:
    try:
        return Path(f"/proc/{pid}/stat").read_text().split(") ")[1][0] != "Z"
    except (OSError, IndexError):
        return False


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="/proc")
@pytest.mark.parametrize("start", ["", "forkserver"])
def test_kill_minus_nine_with_workers_leaves_no_process_and_no_lock(tmp_path, start):
    """kill -9 of a 2-worker batch: the workers end with it (they do not wait forever
    for inputs that never come, nor keep the output directory locked); the re-run
    then finishes the batch.  Forked workers (the default) and a fork server's."""
    src = _half_days(tmp_path / "in", 8)
    out = tmp_path / "out"
    cmd = [sys.executable, "-m", "accal", "grace-bias", str(src), "-r", "-j", "2", "-q"]
    proc = subprocess.Popen(
        [*cmd, "--out", str(out)],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        env={**os.environ, "ACCAL_START_METHOD": start},
    )
    deadline = time.monotonic() + 120
    workers: set[int] = set()
    while time.monotonic() < deadline and not list(out.glob("*.report.json")):
        workers |= _descendants(proc.pid)
        time.sleep(0.02)
    workers |= _descendants(proc.pid)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    assert len(list(out.glob("*.report.json"))) < 8, "the batch was not killed mid-way"
    assert len(workers) >= 2, workers
    deadline = time.monotonic() + 20
    while time.monotonic() < deadline and any(_alive(p) for p in workers):
        time.sleep(0.05)
    assert not [p for p in workers if _alive(p)], "processes of the killed batch still run"
    res = subprocess.run([*cmd, "--out", str(out)], capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    assert len(json.loads((out / "manifest.json").read_text())["entries"]) == 8


def test_start_method_forks_only_a_single_threaded_process():
    """Workers are forked (no fresh interpreter to import the libraries) only while no
    other thread runs; with one, a fork server starts them."""
    import threading

    from accal.batch import start_method

    code = (  # as the CLI starts: one BLAS thread (else the BLAS's own threads count)
        "from accal._runtime import single_threaded_blas; single_threaded_blas(); "
        "from accal.batch import start_method; print(start_method())"
    )
    env = {k: v for k, v in os.environ.items() if k != "ACCAL_START_METHOD"}
    res = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, env=env
    )
    assert res.stdout.strip() == ("fork" if sys.platform.startswith("linux") else "forkserver")
    stop = threading.Event()
    other = threading.Thread(target=stop.wait)
    other.start()
    try:
        assert start_method() == "forkserver"
    finally:
        stop.set()
        other.join()


def test_start_method_can_be_forced_and_a_bad_value_is_a_usage_error(monkeypatch, tmp_path):
    from accal.batch import start_method
    from accal.errors import AccalError

    monkeypatch.setenv("ACCAL_START_METHOD", "Spawn")
    assert start_method() == "spawn"
    monkeypatch.setenv("ACCAL_START_METHOD", "thread")
    with pytest.raises(AccalError, match="ACCAL_START_METHOD='thread': use 'fork', 'forkserver'"):
        start_method()
    # at once, whatever the number of workers, before any output exists
    code, _, err = invoke("grace-bias", "x.asc", "--out", tmp_path / "o", "-j", "1")
    assert code == 2 and err.strip().startswith("accal: ACCAL_START_METHOD='thread': use")
    assert not (tmp_path / "o").exists()


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="/proc")
def test_rerun_into_an_existing_table_still_forks_and_logs_how(archive, tmp_path):
    """Reading the existing table must not start threads (pyarrow's pools would make
    the workers start from a fork server); the log says how the workers started."""
    env = {k: v for k, v in os.environ.items() if k != "ACCAL_START_METHOD"}
    out = tmp_path / "o"
    cmd = [sys.executable, "-m", "accal", "grace-bias", "--out", str(out), "-j", "2", "-q"]
    files = sorted(str(p) for p in archive.rglob("ACC1B_*.asc"))
    for chunk in (files[:2], files[2:]):  # the second run reads the first one's table
        subprocess.run([*cmd, *chunk], check=True, env=env, capture_output=True)
    starts = [x for x in (out / "accal.log").read_text().splitlines() if "inputs run in" in x]
    assert len(starts) == 2 and all(x.endswith("2 worker processes (fork)") for x in starts)


@pytest.mark.skipif(not hasattr(os, "fork"), reason="fork")
def test_a_forked_child_does_not_hold_the_output_lock(tmp_path):
    """flock belongs to the open file, which a fork shares: the child must drop it, or a
    worker would keep the directory locked after its batch ended."""
    lock = OutputLock(tmp_path, "parent")
    lock.acquire()
    started_r, started_w = os.pipe()
    done_r, done_w = os.pipe()
    pid = os.fork()
    if pid == 0:  # the child: say it runs, then keep what it inherited until told to end
        os.write(started_w, b"1")
        os.read(done_r, 1)
        os._exit(0)
    try:
        assert os.read(started_r, 1) == b"1"  # the child's fork handlers have run
        lock.release()
        with OutputLock(tmp_path, "next run"):  # raises LockedError if the child held it
            pass
    finally:
        os.write(done_w, b"1")
        os.waitpid(pid, 0)
        for fd in (started_r, started_w, done_r, done_w):
            os.close(fd)


# ---------------------------------------------------------------- accal table


def test_table_prints_filters_and_exports(archive, tmp_path):
    out = tmp_path / "o"
    assert invoke("grace-bias", archive, "-r", "--out", out, "--method", "both", "-q")[0] == 0
    code, text, _ = invoke("table", out)
    assert code == 0
    assert len(text.strip().splitlines()) == 1 + 6 * 3 * 2
    code, text, _ = invoke(
        "table", out, "--satellite", "B", "--start", "2005-01-02", "--method", "lsq"
    )
    lines = text.strip().splitlines()
    assert len(lines) == 1 + 2 * 3
    assert all("GRACE-B" in line for line in lines[1:])
    code, _, err = invoke(
        "table", out, "--end", "2005-01-01", "--axis", "x", "--export", tmp_path / "x.csv"
    )
    assert code == 0, err
    df = pd.read_csv(tmp_path / "x.csv", comment="#")
    assert len(df) == 2 * 2 and set(df["axis"]) == {"x"} and set(df["date"]) == {"2005-01-01"}
    assert np.isfinite(df["bias"]).all()
    code, _, err = invoke("table", out, "--start", "2005-13-01")
    assert code != 0 and "YYYY-MM-DD" in err
    code, _, err = invoke("table", tmp_path)
    assert code == 1 and "no bias_drift" in err


def test_table_merge_stays_fast_enough_at_mission_scale(tmp_path):
    """66,000 rows (11,000 days x 3 axes x 2 methods): merging a day in keeps every row
    once (the timing itself is in `make bench-archive`, not asserted here)."""
    from accal.pipeline import BIAS_DRIFT_UNITS, merge_bias_drift, read_bias_drift

    n_days = 11000
    rows = []
    base = np.datetime64("2002-04-01")
    for d in range(n_days):
        date = str(base + np.timedelta64(d, "D"))
        for ax in "xyz":
            for m in ("wavelet", "lsq"):
                rows.append(_row(f"ACC1B_{date}_A_02.dat", date, ax, m))
    merge_bias_drift(tmp_path, rows, "parquet")
    new = [_row("ACC1B_2002-04-01_A_02.dat", "2002-04-01", "x", "lsq", bias=1.0)]
    new.append(_row("ACC1B_2040-01-01_A_02.dat", "2040-01-01", "x", "lsq"))
    merge_bias_drift(tmp_path, new, "parquet")
    df = read_bias_drift(tmp_path / "bias_drift.parquet")
    assert len(df) == n_days * 6 + 1
    assert set(df.columns) == set(BIAS_DRIFT_UNITS)
    hit = df[(df.source == "ACC1B_2002-04-01_A_02.dat") & (df.axis == "x") & (df.method == "lsq")]
    assert hit["bias"].tolist() == [1.0]


def _row(source: str, date: str, ax: str, m: str, bias: float = 1e-6) -> dict:
    from accal.pipeline import BIAS_DRIFT_UNITS

    row = {k: float("nan") for k in BIAS_DRIFT_UNITS}
    row.update(
        source=source, satellite="GRACE-A", date=date, axis=ax, frame="SRF", method=m,
        order=1, bias=bias, n=86400, n_total=86400, n_flagged=0, n_duplicates=0,
        n_out_of_order=0, n_gaps=0, accal_version="0", model="poly1", sigma_model="day",
        sigma_days=1, n_thruster=0,
    )  # fmt: skip
    return row


# ---------------------------------------------------------------- degraded days


def test_degraded_days_are_flagged_in_the_table(tmp_path):
    """GRACE-FO D (transplant) and GRACE-B in 2017 (transplant) are flagged; a user table
    can add periods; `accal table --status` filters on it."""
    from accal.simulate.grace import write_simulated_grace

    b2017 = tmp_path / "ACC1B_2017-03-01_B_02.asc"
    write_simulated_grace(b2017, date="2017-03-01", satellite="B", seed=1, duration=3600.0)
    a2005 = tmp_path / "ACC1B_2005-06-01_A_02.asc"
    write_simulated_grace(a2005, date="2005-06-01", satellite="A", seed=2, duration=3600.0)
    user = tmp_path / "periods.toml"
    user.write_text(
        '[[period]]\nsatellite = "GRACE-A"\nstart = 2005-06-01\nend = 2005-06-01\n'
        'status = "degraded"\nreason = "thruster anomaly (user table)"\n'
    )
    out = tmp_path / "o"
    code, _, err = invoke(
        "grace-bias", SAMPLES / "ACT1B_2023-06-01_D_04.txt", SAMPLES / "ACT1B_2023-06-01_C_04.txt",
        b2017, a2005, "--degraded-days", user, "--out", out, "-q",
    )  # fmt: skip
    assert code == 0, err
    df = read_outputs(out)["table"].groupby("source").first()
    assert df.loc["ACT1B_2023-06-01_D_04.txt", "day_status"] == "transplant"
    assert "GRACE-C" in df.loc["ACT1B_2023-06-01_D_04.txt", "day_status_reason"]
    assert df.loc["ACT1B_2023-06-01_C_04.txt", "day_status"] == "nominal"
    assert df.loc["ACT1B_2023-06-01_C_04.txt", "day_status_reason"] == ""
    assert df.loc[b2017.name, "day_status"] == "transplant"
    assert df.loc[a2005.name, "day_status"] == "degraded"
    assert "user table" in df.loc[a2005.name, "day_status_reason"]
    code, text, _ = invoke("table", out, "--status", "nominal", "--axis", "x")
    assert code == 0
    assert text.strip().splitlines()[1].split()[0] == "ACT1B_2023-06-01_C_04.txt"
    assert len(text.strip().splitlines()) == 2

    # a GRACE-B day while its accelerometer was off: processed, flagged, and said
    b_off = tmp_path / "ACC1B_2016-10-01_B_02.asc"
    write_simulated_grace(b_off, date="2016-10-01", satellite="B", seed=3, duration=3600.0)
    code, _, err = invoke("grace-bias", b_off, "--out", out)
    assert code == 0, err
    assert f"accal: {b_off}: warning: instrument off on this day (" in err
    assert (
        read_outputs(out)["table"].set_index("source").loc[b_off.name, "day_status"].eq("off").all()
    )


def _terminal_signals() -> None:
    """In the child before exec: SIGINT and SIGTERM as a terminal gives them (default
    action, not blocked).  A signal mask and an ignored disposition are inherited
    across exec, and the test process's may have been changed by what ran before it
    in the same session (the batch then never saw the SIGINT and exited 0, in full
    runs only)."""
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT, signal.SIGTERM})
    signal.signal(signal.SIGINT, signal.SIG_DFL)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)


@pytest.mark.skipif(sys.platform == "win32", reason="POSIX signals")
@pytest.mark.parametrize("sig", ["SIGINT", "SIGTERM"])
def test_ctrl_c_stops_the_batch_at_once_and_keeps_what_finished(tmp_path, sig):
    """SIGINT to the process group (Ctrl-C) mid-batch with 2 workers: exit 130 at once,
    the finished inputs are in the table and manifest, no temporaries; a re-run finishes.
    SIGTERM to the batch process alone (``timeout``, systemd) does the same (QA: it
    left hidden temporaries behind)."""
    from accal.simulate.grace import write_simulated_grace

    src = tmp_path / "in"
    # 12 h days: the batch must still be running well after its first input is done
    # (measured: first "ok" at 4.6 s, end at 11 s; with 3 h days the batch ended 1.8 s
    # after its first "ok" once closure got faster, and the signal came too late)
    for k in range(6):
        write_simulated_grace(
            src / f"ACC1B_2005-01-0{k + 1}_A_02.asc", date=f"2005-01-0{k + 1}", satellite="A",
            duration=43200.0,
        )  # fmt: skip
    out = tmp_path / "out"
    cmd = [sys.executable, "-m", "accal", "grace-bias", str(src), "-r", "-j", "2", "--close-loop"]
    proc = subprocess.Popen(
        [*cmd, "--out", str(out), "-q"],
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
        preexec_fn=_terminal_signals,
    )
    log = out / "accal.log"
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and proc.poll() is None:
        if log.exists() and " ok " in log.read_text():
            break
        time.sleep(0.05)
    assert proc.poll() is None, "the batch finished before it could be interrupted"
    if sig == "SIGINT":
        os.killpg(proc.pid, signal.SIGINT)
    else:
        os.kill(proc.pid, signal.SIGTERM)
    t0 = time.monotonic()
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130 and time.monotonic() - t0 < 10
    assert "interrupted:" in err and "Traceback" not in err
    done = {r.split()[-3].rstrip(":") for r in log.read_text().splitlines() if " ok " in r}
    df = pd.read_parquet(out / "bias_drift.parquet")
    assert {Path(p).name for p in done} == set(df["source"]) and len(done) < 6
    assert not [p for p in out.iterdir() if p.name.endswith(".tmp")]
    rerun = subprocess.run([*cmd, "--out", str(out), "-q"], capture_output=True, text=True)
    assert rerun.returncode == 0, rerun.stderr
    assert len(pd.read_parquet(out / "bias_drift.parquet")) == 6 * 3


@pytest.mark.skipif(sys.platform == "win32", reason="POSIX file descriptors")
def test_runs_with_stderr_closed(archive, tmp_path):
    """QA: with stderr closed (``2>&-`` in a crontab) and no -q, accal exited 1 at once
    and silently (``sys.stderr`` is None); the batch runs and the log has it."""
    out = tmp_path / "o"
    cmd = [sys.executable, "-m", "accal", "grace-bias", str(archive), "-r", "--out", str(out)]
    res = subprocess.run(cmd, stdout=subprocess.PIPE, preexec_fn=lambda: os.close(2))  # noqa: PLW1509
    assert res.returncode == 0
    assert "accal grace-bias: 6 ok" in (out / "accal.log").read_text()


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="SIGKILL, fork")
@pytest.mark.parametrize("start", ["fork", "forkserver"])
def test_a_worker_killed_mid_batch_fails_only_its_input(tmp_path, start):
    """QA: one worker killed (the OOM killer) broke the pool, and every input not yet
    finished was reported as an internal error.  Only the input that killed its
    worker fails, saying how; the others are redone and succeed."""
    script = tmp_path / "killer.py"
    script.write_text(
        "import os, signal, sys\n"
        "from pathlib import Path\n"
        "def task(p):\n"
        "    if p.name.startswith('KILL'):\n"
        "        os.kill(os.getpid(), signal.SIGKILL)\n"
        "    return p.name\n"
        "if __name__ == '__main__':\n"
        "    from accal.batch import execute\n"
        "    from accal.pipeline import _internal_error\n"
        "    paths = [Path(f'{i:02d}.asc') for i in range(12)]\n"
        "    paths[5] = Path('KILL.asc')\n"
        "    notes = []\n"
        "    got = dict(execute(task, paths, workers=2, on_error=lambda p, e: 'ERR ' + "
        "_internal_error(p, e).message, on_note=notes.append))\n"
        "    for i in sorted(got): print(got[i])\n"
        "    print('NOTES', notes)\n"
    )
    env = {**os.environ, "ACCAL_START_METHOD": start, "PYTHONPATH": str(tmp_path)}
    res = subprocess.run(
        [sys.executable, str(script)], capture_output=True, text=True, env=env, timeout=120
    )
    assert res.returncode == 0, res.stderr
    lines = res.stdout.splitlines()
    assert lines[:5] + lines[6:12] == [f"{i:02d}.asc" for i in range(12) if i != 5]
    # how it ended is said when the exit code is still there to read (usually:
    # "was killed by SIGKILL (out of memory? ...)"); the pool may have reaped it
    # first ("ended abruptly"), and a fork server that lost track of its child
    # reports 255 ("exited abruptly (exit codes [255])")
    assert lines[5].startswith("ERR KILL.asc: the worker process running this input ")
    assert any(s in lines[5] for s in ("SIGKILL", "ended abruptly", "exit codes [255]"))
    assert "a worker process died" in lines[12]


def test_a_pattern_that_matches_nothing_counts_as_failed(archive, tmp_path):
    """QA: it printed an error line but the summary did not count it (4 error lines,
    '3 failed'), and the log (what a cron job mails) did not have it."""
    one = next(archive.rglob("ACC1B_*.asc"))
    code, _, err = invoke("grace-bias", one, tmp_path / "nope*.asc", "--out", tmp_path / "o")
    assert code == 1
    assert f"accal: {tmp_path / 'nope*.asc'}: no file matches this pattern" in err
    assert "1 ok, 0 skipped (current), 1 failed, 0 not run" in err
    assert "FAILED " in (tmp_path / "o" / "accal.log").read_text()


def test_prefetch_reads_regular_files_ahead_and_ignores_everything_else(tmp_path, monkeypatch):
    """The read-ahead of the next inputs is advice: a regular file gets
    POSIX_FADV_WILLNEED over its whole length; a missing path, a directory, a FIFO
    with no writer (it must not block) or None get nothing, and nothing raises."""
    from accal import batch

    calls = []
    real = os.posix_fadvise
    monkeypatch.setattr(
        os,
        "posix_fadvise",
        lambda fd, off, n, adv: (calls.append((off, n, adv)), real(fd, off, n, adv)),
    )
    f = tmp_path / "day.asc"
    f.write_bytes(b"x" * 100_000)
    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)
    for p in (None, tmp_path / "missing.asc", tmp_path, fifo):
        batch.prefetch(p)
    assert calls == []
    batch.prefetch(f)
    assert calls == [(0, 0, os.POSIX_FADV_WILLNEED)]


def test_a_batch_reads_ahead_the_inputs_the_workers_take_next(archive, tmp_path, monkeypatch):
    """With W workers the first W inputs are read by the workers at once; every
    later input is read ahead exactly once, in the order the pool hands them out."""
    from accal import batch

    paths = sorted(archive.rglob("ACC1B_*.asc"))[:6]
    # forked workers find _name_of in this module (a fork server would import it anew)
    monkeypatch.setenv("ACCAL_START_METHOD", "fork")
    seen: list[Path] = []
    monkeypatch.setattr(batch, "prefetch", lambda p: seen.append(p) if p is not None else None)
    got = dict(batch.execute(_name_of, paths, workers=2, on_error=lambda p, e: repr(e)))
    assert sorted(got.values()) == sorted(p.name for p in paths)
    assert seen == paths[2:]


def _name_of(p: Path) -> str:
    return p.name


def test_sigterm_mid_write_leaves_no_temporary(tmp_path):
    """QA: ``accal simulate gap`` killed by SIGTERM (``timeout``) left a hidden
    ``.run.parquet.*.tmp`` of gigabytes that nothing removed.  SIGTERM is an interrupt
    in the accal process: the file being written is removed, the target not created."""
    script = tmp_path / "term.py"
    script.write_text(
        "import os, signal, sys, time\n"
        "import pyarrow.parquet as pq\n"
        "real = pq.ParquetWriter.write_table\n"
        "def write_then_term(self, *a, **k):\n"  # the first chunk of the run is written
        "    real(self, *a, **k)\n"
        "    os.kill(os.getpid(), signal.SIGTERM)\n"
        "    time.sleep(30)\n"
        "pq.ParquetWriter.write_table = write_then_term\n"
        "from accal.__main__ import main\n"
        "sys.argv = ['accal', 'simulate', 'gap', '--days', '0.05', '--out', sys.argv[1]]\n"
        "main()\n"
    )
    out = tmp_path / "o" / "run.parquet"
    t0 = time.monotonic()
    res = subprocess.run(
        [sys.executable, str(script), str(out)], capture_output=True, text=True, timeout=60
    )
    assert res.returncode != 0 and time.monotonic() - t0 < 25
    assert "Traceback" not in res.stderr
    assert sorted(p.name for p in out.parent.iterdir()) == []  # no target, no temporary


# ---------------------------------------------------------------- a table lost or replaced


def test_deleted_table_is_rebuilt_by_the_next_run(archive, tmp_path):
    """QA: with the table deleted, every input was 'current' and the run wrote no table.

    An input is current only while its rows are in the table: the next run redoes
    them and the table comes back identical.
    """
    out = tmp_path / "o"
    assert invoke("grace-bias", archive, "-r", "--out", out, "-q", "-j", "1")[0] == 0
    before = read_outputs(out)
    (out / "bias_drift.parquet").unlink()
    code, _, err = invoke("grace-bias", archive, "-r", "--out", out, "-j", "1")
    assert code == 0 and "6 ok, 0 skipped" in err
    after = read_outputs(out)
    pd.testing.assert_frame_equal(before["table"], after["table"], check_exact=True)
    code, _, err = invoke("grace-bias", archive, "-r", "--out", out, "-j", "1")
    assert code == 0 and "0 ok, 6 skipped" in err  # and current again


def test_export_cannot_replace_the_live_table(archive, tmp_path):
    """QA: exporting B's rows over OUT/bias_drift.parquet lost A's rows for good."""
    out = tmp_path / "o"
    assert invoke("grace-bias", archive, "-r", "--out", out, "-q", "-j", "1")[0] == 0
    table = (out / "bias_drift.parquet").read_bytes()
    for name in ("bias_drift.parquet", "bias_drift.csv", "BIAS_DRIFT.parquet"):
        code, _, err = invoke("table", out, "--export", out / name, "--satellite", "B")
        assert code == 2 and "is the name of the cumulative table" in err
    assert (out / "bias_drift.parquet").read_bytes() == table
    assert not (out / "bias_drift.csv").exists()
    code, _, err = invoke("table", out, "--export", tmp_path / "nope" / "x.csv")
    assert code == 2 and "does not exist" in err and not (tmp_path / "nope").exists()
    code, _, err = invoke("table", out, "--export", tmp_path / "b.csv", "--satellite", "B")
    assert code == 0 and len(pd.read_csv(tmp_path / "b.csv", comment="#")) == 9


def test_damaged_table_fails_every_run_not_only_when_work_is_due(archive, tmp_path):
    """QA: a truncated table went unnoticed (exit 0) while every input was current."""
    out = tmp_path / "o"
    assert invoke("grace-bias", archive, "-r", "--out", out, "-q", "-j", "1")[0] == 0
    t = out / "bias_drift.parquet"
    t.write_bytes(t.read_bytes()[:500])
    code, _, err = invoke("grace-bias", archive, "-r", "--out", out, "-j", "1")
    assert code == 1 and "damaged bias_drift table" in err and str(t) in err


@pytest.mark.parametrize("damage", ["drop drift", "duplicate a row"])
def test_table_with_a_damaged_schema_or_duplicate_rows_fails_every_run(archive, tmp_path, damage):
    """Issue 23: a table with a column dropped was accepted (the next run wrote NaN
    drifts for every untouched input, which stayed "current"); hand-injected duplicate
    rows survived.  Both are the damaged-table error a truncated table gets."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    out = tmp_path / "o"
    assert invoke("grace-bias", archive, "-r", "--out", out, "-q", "-j", "1")[0] == 0
    t = out / "bias_drift.parquet"
    tab = pq.read_table(t)
    if damage == "drop drift":
        tab = tab.drop_columns(["drift"])
        says = "no drift column"
    else:
        tab = pa.concat_tables([tab, tab.slice(0, 1)])
        says = "more than once"
    pq.write_table(tab, t)
    before = t.read_bytes()
    code, _, err = invoke("grace-bias", archive, "-r", "--out", out, "-j", "1")
    assert code == 1 and "damaged bias_drift table" in err and says in err and str(t) in err
    assert t.read_bytes() == before  # left as it is, for the user to look at


def test_date_is_the_day_of_a_file_that_starts_before_midnight(tmp_path):
    """QA: a 2005-01-01 file whose first record is 10 s before midnight was dated
    2004-12-31 (the day of t0), and ``--start 2005-01-01`` missed it."""
    from accal.io.grace_l1b import read_grace_acc1b, write_grace_acc1b
    from accal.simulate.grace import write_simulated_grace

    f = tmp_path / "ACC1B_2005-01-01_A_02.asc"
    write_simulated_grace(f, date="2005-01-01", satellite="A", seed=1, duration=7200.0)
    s = read_grace_acc1b(f)
    write_grace_acc1b(s.replace(time=s.time - 10.0), f)
    out = tmp_path / "o"
    assert invoke("grace-bias", f, "--out", out, "-q")[0] == 0
    code, text, _ = invoke("table", out, "--start", "2005-01-01", "--end", "2005-01-01")
    assert code == 0 and text.count("ACC1B_2005-01-01_A_02.asc") == 3
    from accal.pipeline import read_bias_drift

    t = read_bias_drift(out / "bias_drift.parquet")
    assert set(t["date"]) == {"2005-01-01"} and (t["t0"] < 157809600.0).all()


def test_diagnose_refuses_a_directory_in_use(archive, tmp_path):
    """QA: diagnose ran (exit 0) beside a grace-bias run holding DIR, reading half-written files."""
    out = tmp_path / "o"
    one = next(archive.rglob("ACC1B_2005-01-01_A_02.asc"))
    assert invoke("grace-bias", one, "--out", out, "-q")[0] == 0
    with OutputLock(out, "accal grace-bias"):
        code, _, err = invoke("diagnose", out, "-q")
    assert code == 1 and "output directory is in use by another accal run" in err
    assert not (out / "diagnose").exists()
    assert invoke("diagnose", out, "-q")[0] == 0  # and released after
    assert (out / "diagnose" / "closure.json").exists()


def test_table_missing_some_rows_of_a_source_redoes_it(archive, tmp_path):
    """QA: with a source's lsq rows gone from the table it was still 'current'."""
    import pyarrow.compute as pc
    import pyarrow.parquet as pq

    out = tmp_path / "o"
    args = ("grace-bias", archive, "-r", "--out", out, "-j", "1", "--method", "both")
    assert invoke(*args, "-q")[0] == 0
    before = read_outputs(out)["table"]
    t = pq.read_table(out / "bias_drift.parquet")
    pq.write_table(t.filter(pc.equal(t["method"], "wavelet")).slice(1), out / "bias_drift.parquet")
    code, _, err = invoke(*args)
    assert code == 0 and "6 ok, 0 skipped" in err
    pd.testing.assert_frame_equal(read_outputs(out)["table"], before, check_exact=True)
