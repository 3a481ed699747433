"""``adcs replay BAG``: recorded inputs published driver-like (:mod:`.live`) or frame by frame
in lockstep (:mod:`.lockstep`)."""
from adcs_nodes.tools.replay.cli import add_arguments, run_from_args  # noqa: F401
from adcs_nodes.tools.replay.common import restamp  # noqa: F401
from adcs_nodes.tools.replay.live import load_samples  # noqa: F401
from adcs_nodes.tools.replay.lockstep import write_params  # noqa: F401
