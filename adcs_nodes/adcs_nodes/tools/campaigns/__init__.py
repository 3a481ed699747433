"""``adcs montecarlo``: dispersed closed-loop campaigns, local or on a Dask cluster, resumable.

Usage::

    adcs montecarlo SCENARIO --runs N [--jobs J] [--scheduler ADDRESS | --dask-local] [--out DIR]
                    [--duration S] [--seed S] [--max-rate-deg-s W] [--capture-deg 5.0]
                    [--mag-bias-nT B] [--misalignment-deg M] [--auto-detumble]
                    [--bdot-gain K] [--engine auto|graph|plain] [--compose]

Dispersions
-----------
Run ``i`` of a campaign with seed ``s`` draws, from ``numpy.random.default_rng([s, i])`` and in
this order (the order is part of the file format: changing it changes every campaign):

1. ``q_orbit_body`` uniform on SO(3): a 4-D standard normal vector, normalised, sign chosen
   with ``w >= 0`` (scalar last);
2. ``omega_body_eci_body``: each body component uniform in ``[-max_rate, +max_rate]`` deg/s
   (the magnitude reaches ``sqrt(3) max_rate``). Default ``max_rate`` by the scenario's paper
   (:data:`~.config.MAX_RATE_BY_PAPER_DEG_S`): paper 000, 3 deg/s (issue 5: "initial rates up
   to 3 deg/s" per axis; the paper's (-3, 3, 3) deg/s is a corner of that cube); paper 001,
   0.3 deg/s (ASSUMPTION: its initial rates (0.3, -0.3, 0.3) deg/s are a corner, and the
   wheels' 55 N m s absorb that tumble; 3 deg/s would saturate them); any other scenario,
   3 deg/s. ``--max-rate-deg-s`` wins;
3. magnetometer bias: each sensor axis uniform in ``+-mag_bias`` nT (only with
   ``--mag-bias-nT``; by default the scenario's bias is kept: "the scenario's sensor errors");
4. magnetometer misalignment: a body -> sensor rotation vector, each component uniform in
   ``+-misalignment`` deg (only with ``--misalignment-deg``; default: the scenario's);
5. the run's scenario ``seed`` (sensor noise, random torque): an integer in ``[0, 2**31 - 1)``.

Every draw is made even when it is not applied (no magnetometer, or the scenario's errors
kept), so a run's values never depend on the scenario's sensor set or these options.

``--auto-detumble`` writes the manager's automatic sequence into each run
(:data:`~adcs_nodes.tools.campaigns.config.AUTO_DETUMBLE`: B-dot until the rate is below
0.5 deg/s, then the magnetic law), with ``--bdot-gain`` as the B-dot gain.

Metrics of a run (:mod:`adcs_nodes.tools.analyse.metrics`, the same definitions as ``adcs report``)
------------------------------------------------------------------------------------------
Captured: the angle between the body and the attitude the scenario's guidance commands
(``adcs/attitude_target``, :mod:`.capture`) enters ``--capture-deg`` and then stays below twice
that to the end. Per scenario: the orbit frame for paper 000 (no guidance profile: the
guidance holds the orbit frame; the numbers are those of the angle to the orbit frame, bit
for bit), paper 001's profile for paper001_mpi (its maneuvers, holds and sine tracking; the
samples of a maneuver segment, whose target is the attitude due at the segment's end, are not
judged). "Captured within 4 orbits" compares that time with 4 orbits of the scenario's
circular orbit; the hold is the angle from 4 orbits to the end (RMS, median, 95th
percentile); the last exit from the band is reported as ``last_exit_s``. Each result says
what its angle was measured to (``capture_reference``: ``orbit frame`` or ``guidance
target``).

Execution
---------
Engine (:mod:`.engine`): ``--engine auto`` (the default) is ``plain`` for every scenario
without an external sensor, else ``graph``; a campaign being resumed keeps the engine recorded
in its ``campaign.json``. The command's first line names the engine and why. Engine ``graph``:
each run is one ``python -m adcs_nodes.tools.campaigns _worker RUN_DIR`` process that starts
the graph with :class:`~adcs_nodes.tools.run.launcher.Launcher` in its own main thread (the
launcher needs signal handlers and sets ``ROS_DOMAIN_ID`` in its environment; a fresh process
per run keeps every graph isolated, each with its own domain). ``--jobs J`` supervises J such
processes at once from a thread pool; ``--scheduler ADDRESS`` submits the same supervisor
function (:func:`execute_run`) to an existing Dask distributed scheduler, whose workers start
the run processes on their machines. Workers need this package (and ROS 2) installed and
``--out`` on a file system they see under the same path. ``--dask-local`` starts a Dask
``LocalCluster`` of J worker processes with one thread each (a worker supervises one run at a
time, like one slot of the thread pool) for the campaign and stops it at the end. Engine
``plain``: the run process is ``python -m adcs_nodes.tools.campaigns.worker RUN_DIR``, the
FrameLoop:
the graph's components without ROS (the same series as the graph to the last bit, the engine
parity test; no bag, the per-frame series go to ``series.npz``), a few seconds of CPU for a
6-orbit paper000_control run against 60-185 s for the graph (docs/montecarlo.md). Every run
process gets one BLAS/OpenMP thread (:data:`.runner.ONE_THREAD_ENV`) and loads the numba
kernels from their on-disk cache.

Files (``OUT`` = ``--out``)
---------------------------
``campaign.json``
    The campaign's identity (:data:`IDENTITY_KEYS`: scenario content hash, seed, duration,
    dispersion bounds, capture threshold, engine, capture reference) plus the last ``runs``
    and ``compose``; a restart with a different identity is refused (a ``campaign.json``
    from before the guidance target measured capture to the orbit frame: it resumes where
    the scenario's guidance holds the orbit frame, as paper 000's, with the same numbers, and
    is refused for any other, as paper 001's). ``--runs``, ``--jobs``, ``--scheduler``,
    ``--dask-local`` and ``--compose`` may change between restarts (run ``i``'s draws depend
    only on the seed and ``i``, so a larger ``--runs`` extends the campaign; composed and
    per-process graphs give the same trajectory).
``runs/run_<i>/``
    ``scenario.yaml`` (the dispersed scenario: ``adcs run`` reproduces the run), ``job.json``,
    ``bag/`` (rosbag2 MCAP), ``logs/``, ``worker.log`` and ``result.json`` (written atomically
    when the run completed; its presence, with the bag, marks the run as done).
``campaign.csv``
    One row per run (:data:`CSV_COLUMNS`): dispersed values, status, metrics and the initial
    truth read back from the bag's first ``/sim/state``.
``summary.md``, ``capture_vs_rate.png``
    Success rate, fraction captured within 4 orbits, capture-time and hold-accuracy
    statistics, success rate per initial-rate bin; scatter of capture time against the initial
    rate.

Modules (one concern each): :mod:`.config` (campaign identity, dispersions),
:mod:`.capture` (what capture is measured to), :mod:`.results` (metrics of one run),
:mod:`.files` (atomic files, run directories, lock), :mod:`.runner` (worker process and its
supervisor), :mod:`.backends` (thread pool, Dask),
:mod:`.campaign` (the campaign), :mod:`.table` (``campaign.csv``), :mod:`.summary`
(``summary.md``, plot), :mod:`.cli` (arguments, entry points).

Status of a run: ``captured`` (see the metrics above), ``not_captured`` (completed, never
captured), ``error`` (the
graph failed: message in the table, rerun on restart), ``interrupted`` / ``pending``
(Ctrl-C; rerun on restart). Exit codes: 0 every run completed, 1 some run failed, 2 bad
arguments, 130 interrupted.
"""
from adcs_nodes.tools.campaigns.backends import DaskBackend, LocalBackend
from adcs_nodes.tools.campaigns.campaign import Campaign
from adcs_nodes.tools.campaigns.capture import (GUIDANCE_TARGET, ORBIT_FRAME,
                                                capture_reference, label_old_result)
from adcs_nodes.tools.campaigns.cli import add_arguments, config_from_args, main, run_from_args
from adcs_nodes.tools.campaigns.config import (AUTO_DETUMBLE, ENGINES, IDENTITY_KEYS,
                                               CampaignConfig, CampaignError, Dispersion,
                                               apply_dispersion, default_max_rate_deg_s,
                                               draw_dispersion, scenario_hash)
from adcs_nodes.tools.campaigns.files import (FAILED_FILE, RESULT_FILE, SERIES_FILE,
                                              load_result, run_dir_of, write_json_atomic)
from adcs_nodes.tools.campaigns.results import (STATE_TOPIC, angle_to_target_deg,
                                                bag_metrics, read_truth, series_metrics)
from adcs_nodes.tools.campaigns.runner import (ONE_THREAD_ENV, STOP_GRACE_S, execute_run,
                                               worker_env, worker_main)
from adcs_nodes.tools.campaigns.summary import (orbit_period_s, plot_capture_vs_rate,
                                                rate_bins, summary_markdown)
from adcs_nodes.tools.campaigns.table import CSV_COLUMNS, read_table, table_row, write_table

__all__ = ['AUTO_DETUMBLE', 'CSV_COLUMNS', 'ENGINES', 'FAILED_FILE', 'GUIDANCE_TARGET',
           'IDENTITY_KEYS', 'ONE_THREAD_ENV', 'ORBIT_FRAME', 'RESULT_FILE', 'SERIES_FILE',
           'STATE_TOPIC', 'STOP_GRACE_S', 'Campaign', 'CampaignConfig', 'CampaignError',
           'DaskBackend', 'Dispersion', 'LocalBackend', 'add_arguments', 'angle_to_target_deg',
           'apply_dispersion', 'bag_metrics', 'capture_reference', 'config_from_args',
           'default_max_rate_deg_s', 'draw_dispersion', 'execute_run', 'label_old_result',
           'load_result', 'main', 'orbit_period_s', 'plot_capture_vs_rate', 'rate_bins',
           'read_table', 'read_truth', 'run_dir_of', 'run_from_args', 'scenario_hash',
           'series_metrics', 'summary_markdown', 'table_row', 'worker_env',
           'worker_main', 'write_json_atomic', 'write_table']
