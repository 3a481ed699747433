"""``adcs replay BAG``: publish a bag's recorded inputs so the flight software runs without
``sim_node``.

* Driver-like (:mod:`.live`): the sensor topics (``/sensors/*`` or ``--topics``), each
  message at the wall time its ``header.stamp`` comes due (``--rate``), best-effort,
  ``/tf_static`` latched once, ``/clock`` every 10 ms unless ``--now``; ``--time-offset``
  or ``--now`` shift the stamps (the onboard models then need the shifted ``epoch``, which
  the replay prints).
* Lockstep (:mod:`.lockstep`): the recorded estimates again, bit for bit.

Messages are published as the recorded CDR bytes (only the 8 stamp bytes are rewritten when
a stamp changes). A bag is data: its scenario is read through the scenario file's guards and
its plugins are never imported (:mod:`adcs_nodes.tools.bagfile`). Exit codes: 0 done, 1 a
lockstep node not ready or stalled, 2 bad input, 130 interrupted.
"""
from adcs_nodes.tools.replay.cli import add_arguments, run_from_args  # noqa: F401
from adcs_nodes.tools.replay.common import LockstepStall, ReplayError, restamp  # noqa: F401
from adcs_nodes.tools.replay.live import load_samples, replay  # noqa: F401
from adcs_nodes.tools.replay.lockstep import (lockstep_plan, replay_lockstep,  # noqa: F401
                                              write_params)
