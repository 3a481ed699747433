"""``adcs montecarlo`` and ``adcs sweep``: dispersed closed-loop campaigns, local or on a Dask
cluster, resumable (``docs/montecarlo.md``)."""
from adcs_nodes.tools.campaigns.backends import DaskBackend  # noqa: F401
from adcs_nodes.tools.campaigns.capture import GUIDANCE_TARGET  # noqa: F401
from adcs_nodes.tools.campaigns.cli import add_arguments, run_from_args  # noqa: F401
from adcs_nodes.tools.campaigns.config import (  # noqa: F401
    AUTO_DETUMBLE, CampaignConfig, apply_dispersion, draw_dispersion)
from adcs_nodes.tools.campaigns.files import (  # noqa: F401
    FAILED_FILE, RESULT_FILE, SERIES_FILE, load_result, run_dir_of, write_json_atomic)
from adcs_nodes.tools.campaigns.results import (  # noqa: F401
    bag_metrics, read_truth, series_metrics)
from adcs_nodes.tools.campaigns.runner import close_servers, execute_run  # noqa: F401
from adcs_nodes.tools.campaigns.summary import (  # noqa: F401
    orbit_period_s, plot_capture_vs_rate, summary_markdown)
from adcs_nodes.tools.campaigns.table import CSV_COLUMNS, read_table  # noqa: F401
