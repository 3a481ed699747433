"""``adcs montecarlo``: dispersed closed-loop campaigns, local or on a Dask cluster, resumable.

The dispersions (their draw order is part of the file format), what "captured" means, the
engines, the files of a campaign directory and the exit codes: ``docs/montecarlo.md``.
Modules, one concern each: :mod:`.config` (identity, dispersions), :mod:`.capture` (what
capture is measured to), :mod:`.results` (metrics of one run), :mod:`.files` (atomic files,
run directories, lock, layout), :mod:`.runner` (run process, its owner and supervisor),
:mod:`.backends` (thread pool, Dask), :mod:`.campaign`, :mod:`.table` (``campaign.csv``),
:mod:`.summary` (``summary.md``, plot), :mod:`.cli` (arguments), :mod:`.sweep`.
"""
# the package's names (``from adcs_nodes.tools import campaigns as mc``)
from adcs_nodes.tools.campaigns.backends import DaskBackend, LocalBackend  # noqa: F401
from adcs_nodes.tools.campaigns.campaign import Campaign  # noqa: F401
from adcs_nodes.tools.campaigns.capture import (  # noqa: F401
    GUIDANCE_TARGET, ORBIT_FRAME, capture_reference, label_old_result)
from adcs_nodes.tools.campaigns.cli import (  # noqa: F401
    add_arguments, config_from_args, main, run_from_args)
from adcs_nodes.tools.campaigns.config import (  # noqa: F401
    AUTO_DETUMBLE, ENGINES, IDENTITY_KEYS, CampaignConfig, CampaignError, Dispersion,
    apply_dispersion, default_max_rate_deg_s, draw_dispersion, scenario_hash)
from adcs_nodes.tools.campaigns.files import (  # noqa: F401
    FAILED_FILE, RESULT_FILE, SERIES_FILE, load_result, run_dir_of, write_json_atomic)
from adcs_nodes.tools.campaigns.results import (  # noqa: F401
    STATE_TOPIC, angle_to_target_deg, bag_metrics, read_truth, series_metrics)
from adcs_nodes.tools.campaigns.runner import (  # noqa: F401
    ONE_THREAD_ENV, STOP_GRACE_S, close_servers, execute_run, worker_env, worker_main)
from adcs_nodes.tools.campaigns.summary import (  # noqa: F401
    orbit_period_s, plot_capture_vs_rate, rate_bins, summary_markdown)
from adcs_nodes.tools.campaigns.table import (  # noqa: F401
    CSV_COLUMNS, read_table, table_row, write_table)
