"""Issue 23 findings 2-4: the output directory holds accal's own files only.

* ``--out ""`` (an unset variable in a cron line) is a usage error, not the current
  directory;
* ``OUT/.accal.lock`` or ``OUT/accal.log`` as a symbolic link is refused: the file it
  points at is neither truncated nor appended to;
* the clean-up after a killed run removes accal's temporaries only.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest
from click.testing import CliRunner

from accal.batch import remove_stale_temporaries
from accal.cli import main
from accal.io.writers import atomic_path

SAMPLE = Path(__file__).resolve().parents[1] / "data" / "samples" / "ACC1B_2003-09-14_A_00.asc"


def _run(*args):
    res = CliRunner().invoke(main, [str(a) for a in args])
    return res.exit_code, res.output


@pytest.mark.parametrize("cmd", [["grace-bias", SAMPLE], ["demod", "x.parquet", "--tau", "600",
                                                          "--mask", "200"]])  # fmt: skip
@pytest.mark.parametrize("out", ["", "  "])
def test_empty_out_is_a_usage_error(tmp_path, monkeypatch, cmd, out):
    monkeypatch.chdir(tmp_path)
    code, msg = _run(*cmd, "--out", out)
    assert code == 2 and "empty path (an unset variable?)" in msg
    assert list(tmp_path.iterdir()) == []  # nothing written into the current directory


@pytest.mark.parametrize("name", [".accal.lock", "accal.log"])
def test_a_symlinked_lock_or_log_is_refused_and_its_target_untouched(tmp_path, name):
    victim = tmp_path / "precious.txt"
    victim.write_text("keep me\n")
    out = tmp_path / "out"
    out.mkdir()
    (out / name).symlink_to(victim)
    code, msg = _run("grace-bias", SAMPLE, "--out", out, "-q")
    assert code == 2, msg
    assert "a symbolic link or not a regular file, not accal's own: remove it" in msg
    assert victim.read_text() == "keep me\n"
    assert not list(out.glob("*.calibrated.*"))  # no partial output


def test_cleanup_removes_accal_temporaries_only(tmp_path):
    other = [tmp_path / ".vim.swp.tmp", tmp_path / ".data.csv.1234.tmp", tmp_path / ".x.tmp.bak"]
    for p in other:
        p.write_text("not accal's")
    # a temporary of a killed accal write (atomic_path's own name)
    with pytest.raises(KeyboardInterrupt), atomic_path(tmp_path / "t.parquet") as tmp:
        kept = tmp.with_name(tmp.name + ".png")
        os.link(tmp, kept)  # as a killed plot writer leaves it (.NAME.accal-XXXX.tmp.png)
        raise KeyboardInterrupt
    assert kept.exists()
    assert remove_stale_temporaries(tmp_path) == 1
    assert not kept.exists()
    assert all(p.read_text() == "not accal's" for p in other)


def test_a_manifest_that_is_a_directory_stops_the_run_before_any_output(tmp_path):
    """Issue 23: ``manifest.json`` as a directory failed the run after its outputs were
    written, and the message named a temporary file."""
    out = tmp_path / "out"
    (out / "manifest.json").mkdir(parents=True)
    code, msg = _run("grace-bias", SAMPLE, "--out", out, "-q")
    assert code == 2 and f"{out / 'manifest.json'}: " in msg and ".tmp" not in msg
    assert "not a regular file, not accal's own manifest: remove it" in msg
    assert not list(out.glob("*.calibrated.*")) and not list(out.glob("bias_drift.*"))


def test_a_failed_rename_names_the_target_not_the_temporary(tmp_path):
    (tmp_path / "t.json").mkdir()
    with pytest.raises(OSError) as exc, atomic_path(tmp_path / "t.json") as tmp:
        tmp.write_text("{}")
    assert exc.value.filename == str(tmp_path / "t.json")
    assert not [p for p in tmp_path.iterdir() if p.name.endswith(".tmp")]


def test_a_run_that_processes_nothing_writes_no_manifest(tmp_path):
    """A directory given without ``--recursive``: one clear error, exit 1, and only the
    run's log (and its lock) in the new output directory (QA, 2026-11-29: an empty
    manifest.json too)."""
    inputs = tmp_path / "days"
    inputs.mkdir()
    (inputs / SAMPLE.name).write_bytes(SAMPLE.read_bytes())
    out = tmp_path / "out"
    code, msg = _run("grace-bias", inputs, "--out", out)
    assert code == 1 and "use --recursive" in msg
    assert sorted(p.name for p in out.iterdir()) == [".accal.lock", "accal.log"]
