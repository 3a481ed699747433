"""``adcs replay BAG``: a bag's recorded inputs published driver-like (:mod:`.live`) or frame by
frame to nodes in lockstep (:mod:`.lockstep`), as the recorded CDR bytes (a changed stamp
rewritten); the bag is data (:mod:`adcs_nodes.tools.bagfile`)."""
from adcs_nodes.tools.replay.cli import add_arguments, run_from_args  # noqa: F401
from adcs_nodes.tools.replay.common import restamp  # noqa: F401
from adcs_nodes.tools.replay.live import load_samples  # noqa: F401
from adcs_nodes.tools.replay.lockstep import write_params  # noqa: F401
