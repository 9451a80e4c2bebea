"""Many simulations at once: parameter sweeps run as Ray tasks (``pscc batch``, docs/batch.md).

* :mod:`pscc.batch.key_paths`: key paths into a scene file (``cloth[1].material.density``) and setting a value.
* :mod:`pscc.batch.sweep`: sweep files, checked, and their runs (each scene with each combination of values).
* :mod:`pscc.batch.task`: one run in its run folder (what a Ray task executes; Ray is not needed to call it).
* :mod:`pscc.batch.summary`: ``summary.json`` and ``summary.csv``.
* :mod:`pscc.batch.runner`: :func:`run_batch`, the Ray side: a local instance or a cluster, retries,
  ``--resume``, Ctrl-C.

Ray is imported only when a batch runs (``pip install "pscc[batch]"``).
"""

from __future__ import annotations

from pscc.batch.runner import run_batch as run_batch
from pscc.batch.sweep import Run as Run
from pscc.batch.sweep import Sweep as Sweep
from pscc.batch.sweep import expand_runs as expand_runs
from pscc.batch.sweep import load_sweep as load_sweep

__all__ = ["Run", "Sweep", "expand_runs", "load_sweep", "run_batch"]
