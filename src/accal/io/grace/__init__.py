"""GRACE / GRACE-FO Level-1B accelerometer files (ACC1B, ACT1B): a module a task.

* :mod:`~accal.io.grace.spec`: the file specification (columns, units, qualflg bits,
  binary record, satellites) and its references.
* :mod:`~accal.io.grace.header`: sniffing, size-capped reading, splitting and parsing
  the GRACE ``KEY : value`` and GRACE-FO YAML headers (shared by the other L1B readers).
* :mod:`~accal.io.grace.ascii` and :mod:`~accal.io.grace.binary`: the records.
* :mod:`~accal.io.grace.checks`: satellite ids and the file's day.
* :mod:`~accal.io.grace.acc`: :func:`~accal.io.grace.acc.read_grace_acc1b`.
* :mod:`~accal.io.grace.writer`: :func:`~accal.io.grace.writer.write_grace_acc1b`.

:mod:`accal.io.grace_l1b` re-exports all of these names.
"""
