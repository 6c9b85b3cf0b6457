"""The ``accal grace-bias`` job, one topic a module.

:mod:`accal.pipeline` re-exports the public names of these modules (import from
there):

- :mod:`~accal.gracejob.options`: :class:`GraceBiasOptions`;
- :mod:`~accal.gracejob.outcome`: :class:`FileOutcome`, :class:`RunSummary`;
- :mod:`~accal.gracejob.outputs`: output names, the calibrated columns, JSON files;
- :mod:`~accal.gracejob.reading`: reading an input, subtracting a reference;
- :mod:`~accal.gracejob.fit`: trends, calibration, table rows, :func:`fit_input`;
- :mod:`~accal.gracejob.table`: the ``bias_drift`` table (units, schema, read, merge);
- :mod:`~accal.gracejob.process`: one input end to end (:func:`process_one`);
- :mod:`~accal.gracejob.batch`: a batch (:func:`run`), its commits and manifest key.
"""
