"""What an output directory records: the manifest of the inputs done, and the run log.

:class:`Manifest` remembers, per input, its size, mtime (or SHA-256,
:func:`file_signature`), the accal version, the options and the outputs, so a
re-run skips what is current; :class:`RunLog` appends a line per event to
``OUT/accal.log``.
"""

from __future__ import annotations

import contextlib
import errno
import hashlib
import json
import os
import re
import time as _time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from accal import __version__
from accal.batch_lock import open_own
from accal.io.writers import atomic_path

MANIFEST = "manifest.json"
LOG = "accal.log"


def file_signature(path: Path, checksum: bool = False) -> dict[str, Any]:
    """Size and mtime (ns) of ``path``, plus its SHA-256 with ``checksum``."""
    st = path.stat()
    sig: dict[str, Any] = {"size": st.st_size, "mtime_ns": st.st_mtime_ns}
    if checksum:
        h = hashlib.sha256()
        with open(path, "rb") as fh:
            for chunk in iter(lambda: fh.read(1 << 20), b""):
                h.update(chunk)
        sig["sha256"] = h.hexdigest()
    return sig


@dataclass
class Manifest:
    """What an output directory holds: one entry per input processed there.

    ``entries[key]`` (``key``: the input's resolved path) holds ``size``,
    ``mtime_ns`` (and ``sha256`` with checksums), ``accal_version``, ``options``
    (the canonical options dict), ``outputs`` (file names in the directory),
    ``source`` (the table's key) and ``processed`` (UTC time).
    """

    path: Path
    entries: dict[str, dict[str, Any]] = field(default_factory=dict)
    #: Entries changed since the last :meth:`save` (see :meth:`is_current`).
    changed: bool = field(default=False, compare=False)

    @classmethod
    def load(cls, out_dir: Path) -> Manifest:
        """Read ``OUT/manifest.json`` (an unreadable manifest means: redo everything)."""
        path = Path(out_dir) / MANIFEST
        if os.path.lexists(path) and not path.is_file() or path.is_symlink():
            # found before any input is processed (issue 23: a manifest.json directory
            # failed the run after the outputs, naming a temporary file)
            raise OSError(
                errno.EEXIST, "not a regular file, not accal's own manifest: remove it", str(path)
            )
        try:
            data = json.loads(path.read_text())
            entries = data["entries"] if isinstance(data, dict) else {}
            if not isinstance(entries, dict):
                entries = {}
        except (OSError, ValueError, KeyError):
            entries = {}
        return cls(path, entries)

    @staticmethod
    def key(path: Path) -> str:
        """Manifest key of an input: its resolved absolute path."""
        return os.path.realpath(path)

    def is_current(self, path: Path, options: dict[str, Any], *, checksum: bool = False) -> bool:
        """True if ``path`` was processed with these options by this accal version,
        has not changed since, and all its outputs still exist."""
        e = self.entries.get(self.key(path))
        if not e or e.get("accal_version") != __version__ or e.get("options") != options:
            return False
        use_hash = checksum and "sha256" in e
        try:
            sig = file_signature(path, checksum=use_hash)
        except OSError:
            return False
        # with checksums, a touched but unchanged file is still current
        keys = ("size", "sha256") if use_hash else ("size", "mtime_ns")
        if any(e.get(k) != sig[k] for k in keys):
            return False
        out = self.path.parent
        if not all((out / name).exists() for name in e.get("outputs", ())):
            return False
        if checksum and not use_hash:  # recorded without one: add it (saved with the run)
            with contextlib.suppress(OSError):
                e["sha256"] = file_signature(path, checksum=True)["sha256"]
                self.changed = True
        return True

    def sharing_outputs(self, path: Path, outputs: Sequence[Path]) -> dict[str, dict[str, Any]]:
        """Entries of *other* inputs that name any of ``outputs`` (which ``path`` now wrote)."""
        names = {Path(o).name for o in outputs}
        me = self.key(path)
        return {
            k: e
            for k, e in self.entries.items()
            if k != me and names.intersection(e.get("outputs", ()))
        }

    def record(
        self,
        path: Path,
        options: dict[str, Any],
        outputs: Sequence[Path],
        source: str,
        *,
        checksum: bool = False,
        before: dict[str, Any] | None = None,
        n_rows: int | None = None,
    ) -> None:
        """Record ``path`` as processed (call only after its table rows are merged).

        ``n_rows``: how many table rows it has (a re-run redoes it when fewer are there).

        ``before``: the input's size and mtime taken before it was read.  If the
        file has changed since (replaced while the batch ran), that earlier
        signature is recorded instead, so the next run sees the change and redoes it.
        """
        try:
            sig = file_signature(path, checksum=checksum)
        except OSError:
            return
        if before is not None and any(sig[k] != before.get(k) for k in ("size", "mtime_ns")):
            sig = {k: before[k] for k in ("size", "mtime_ns")}
        self.entries[self.key(path)] = {
            **sig,
            "accal_version": __version__,
            "options": options,
            "outputs": sorted(Path(o).name for o in outputs),
            "source": source,
            "processed": _time.strftime("%Y-%m-%dT%H:%M:%SZ", _time.gmtime()),
        }
        if n_rows is not None:
            self.entries[self.key(path)]["n_rows"] = int(n_rows)

    def save(self) -> None:
        """Write the manifest atomically (not at all while it is empty and no file of
        it exists: a run that processed nothing leaves no manifest, QA 2026-11-29)."""
        self.changed = False
        if not self.entries and not self.path.exists():
            return

        with atomic_path(self.path) as tmp:
            tmp.write_text(
                json.dumps(
                    {"accal_version": __version__, "entries": self.entries},
                    indent=1,
                    sort_keys=True,
                )
                + "\n"
            )


#: C0 and C1 control characters (tab kept) and DEL.
_CONTROL = re.compile(r"[\x00-\x08\x0a-\x1f\x7f-\x9f]")


class RunLog:
    """Append-only text log ``OUT/accal.log`` (one timestamped line per event)."""

    def __init__(self, out_dir: Path, enabled: bool = True) -> None:
        self.path = Path(out_dir) / LOG
        # a file name that is not UTF-8 (bytes kept as surrogates) is logged escaped
        self._fh = (
            open_own(self.path, "a", encoding="utf-8", errors="backslashreplace")
            if enabled
            else None
        )

    def __call__(self, msg: str) -> None:
        if self._fh is not None:
            stamp = _time.strftime("%Y-%m-%dT%H:%M:%S", _time.gmtime())
            # control characters (a file name's terminal escapes, newlines) as \xNN: one
            # line per event, and `cat accal.log` cannot drive the terminal (issue 23)
            msg = _CONTROL.sub(lambda m: f"\\x{ord(m.group()):02x}", msg)
            self._fh.write(f"{stamp}Z [{os.getpid()}] {msg}\n")
            self._fh.flush()

    def close(self) -> None:
        if self._fh is not None:
            self._fh.close()
            self._fh = None
