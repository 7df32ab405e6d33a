"""``coolmuscle batch`` and ``sweep``: many runs side by side (docs/batch.md).

* :mod:`.command` / :mod:`.sweep` - the two commands; :mod:`.commands` registers them;
* :mod:`.job` - one run: what goes to a worker and what comes back (:func:`.job.execute`);
* :mod:`.engine` - where runs happen: in process, a process pool, or Dask;
* :mod:`.report` - the results table and JUnit XML; :mod:`.figures` - a run's figures;
* :mod:`.sweepplot` - ``sweep --plot``.
"""
