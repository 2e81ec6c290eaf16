"""Sweeps: one base scenario, fixed overrides and axes over any scenario keys; every point and
seed simulated, analysed and scored (:func:`twin.harness.chain.run_point`), on all local cores or on a
``dask.distributed`` cluster, with one table of results.

A sweep file (TOML; paths relative to the file)::

    name = "backlash-recovery"            # optional; default: the file's stem
    description = "..."                    # optional
    scenario = "../backlash-steps.toml"    # the base scenario
    seeds = [1, 2]                         # values of the scenario key `seed` (default: its own)

    [set]                                  # fixed overrides, dotted keys as `twin simulate --set`
    "phase2.runs_per_session" = 4          # (or nested: phase2.runs_per_session = 4)
    "degradation.table_backlash_um" = [0.0, 0.0, 10.0]

    [[grid]]                               # grid axes: explicit values ...
    key = "degradation.table_backlash_um[2]"   # `[i]` sets one element of a list
    values = [2.0, 5.0, 10.0]
    [[grid]]                               # ... or start/stop/num, linear or log spaced
    key = ["geometry.straightness_rms_um", "geometry.lateral_straightness_rms_um"]  # tied keys
    start = 0.25
    stop = 1.0
    num = 3
    scale = "log"

    [random]                               # seeded random sampling (combined with the grid)
    n = 8                                  # points drawn
    seed = 7                               # the sweep's own seed
    [[random.axis]]
    key = "sensors.imu_acc_noise_ug_per_rthz"
    low = 2.0
    high = 50.0
    scale = "log"                          # log-uniform; "linear" = uniform

    [reference]                            # Phase I sweeps: the reference data set, simulated
    scenario = "../paper-reference.toml"   # once into OUT/reference before the points
    [reference.set]
    "phase1.captures_per_sample" = 2

The points are the Cartesian product of the grid axes (in file order, the last axis varying
fastest), times the random draws if there are both; every point runs once per seed. Every
point's scenario is validated (:func:`twin.sim.scenario.from_dict`) before anything runs, so a bad
value stops the sweep with the scenario's own message and exit code 2.

Output directory::

    OUT/sweep.json              the expanded sweep (a restart must match it)
    OUT/reference/              the reference data set (if any)
    OUT/points/pNNNN_sSEED/     one campaign directory per point and seed (measurements.h5,
                                truth.h5, phase1/, backlash/, score.json) and result.json,
                                written by the client once the point's task returned
    OUT/sweep-log.jsonl         append-only: per invocation a start line, a line per point
                                computed, an end line with the counts
    OUT/results.parquet, .csv   one row per point and seed (sorted by point, then seed): swept
                                values (columns named by the scenario key), seed, every score
                                (:func:`analysis.scoring.flat`)
    OUT/roc.csv                 detection rate against false-alarm rate over threshold factors,
                                per Phase I method, aggregated over all points and seeds
    OUT/plots/*.png             scores against the swept values; the ROC curves

Executors: by default a ``concurrent.futures.ProcessPoolExecutor`` of ``TWIN_WORKERS`` (else
``os.cpu_count()``) processes (started with ``spawn``; no cluster to start); ``workers=N`` a
``dask.distributed.LocalCluster(n_workers=N, threads_per_worker=1, processes=True)``;
``scheduler=ADDRESS`` an existing cluster, whose workers must see OUT at the same path (a shared
file system), since each task writes its campaign directory there. Each task runs with one BLAS
thread (``threadpoolctl``), so results are bit-identical whichever executor runs them. A worker
lost mid-task is replaced by Dask, which reruns the task; the campaign resumes from its finished
parts. An interrupted sweep rerun with the same command computes only the points without a
``result.json``. The reference data set is simulated by the client on its own cores (all of
them, or N with ``workers=N``) before any point is submitted; it is bit-identical on any number
of processes.
"""

from twin.harness.sweep.plan import Plan, Task, plan_sweep
from twin.harness.sweep.plots import roc_table, write_plots
from twin.harness.sweep.results import method_summary, phase1_methods, records, results_table, summary, write_table
from twin.harness.sweep.runlog import point_dir, read_log, read_result
from twin.harness.sweep.runner import Callbacks, run_sweep, run_task
from twin.harness.sweep.schema import LOG_NAME, MANIFEST_NAME, RESULT_NAME, SweepError, SweepFile, load_sweep

__all__ = [
    "LOG_NAME",
    "MANIFEST_NAME",
    "RESULT_NAME",
    "Callbacks",
    "Plan",
    "SweepError",
    "SweepFile",
    "Task",
    "load_sweep",
    "method_summary",
    "phase1_methods",
    "plan_sweep",
    "point_dir",
    "read_log",
    "read_result",
    "records",
    "results_table",
    "roc_table",
    "run_sweep",
    "run_task",
    "summary",
    "write_plots",
    "write_table",
]
