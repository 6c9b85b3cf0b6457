"""The ``accal demod`` job and its companions, one topic a module.

:mod:`accal.pipeline_demod` re-exports the public names of these modules (import
from there):

- :mod:`~accal.demodjob.options`: :class:`DemodOptions` and the result records;
- :mod:`~accal.demodjob.reading`: the a-priori PSD, the sampling step, checked chunks,
  :func:`estimate`;
- :mod:`~accal.demodjob.table`: the per-period rows of the ``periods`` table;
- :mod:`~accal.demodjob.summary`: the JSON summary of a run;
- :mod:`~accal.demodjob.report`: its warnings and ``summary.md``;
- :mod:`~accal.demodjob.outputs`: file names and checks of the output directory;
- :mod:`~accal.demodjob.closure`: closing the loop (``--close-loop``);
- :mod:`~accal.demodjob.closure_outputs`: the closure's rows and ``closure.json``/``.md``;
- :mod:`~accal.demodjob.batch`: one run file and the batch on the shared runner (:func:`run_demod`);
- :mod:`~accal.demodjob.diagnose`: ``accal diagnose`` on a demod output directory;
- :mod:`~accal.demodjob.planning`: ``accal design`` and ``accal budget``;
- :mod:`~accal.demodjob.simulate`: ``accal simulate gap``.
"""
