"""``adcs replay BAG``: publish a bag's recorded inputs, driver-like (:mod:`.live`) or frame by
frame to nodes in lockstep (:mod:`.lockstep`), as the recorded CDR bytes (only the stamp is
rewritten when it changes); the bag is data (:mod:`adcs_nodes.tools.bagfile`). Exit codes: 0
done, 1 a lockstep node not ready or stalled, 2 bad input, 130 interrupted."""
from adcs_nodes.tools.replay.cli import add_arguments, run_from_args  # noqa: F401
from adcs_nodes.tools.replay.common import LockstepStall, ReplayError, restamp  # noqa: F401
from adcs_nodes.tools.replay.live import load_samples, replay  # noqa: F401
from adcs_nodes.tools.replay.lockstep import (lockstep_plan, replay_lockstep,  # noqa: F401
                                              write_params)
