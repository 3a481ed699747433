"""Moved to :mod:`adcs_nodes.msgs.fields` (kept for ``nodes/lockstep_node.py`` and the tools
until their owners import it from there)."""
from adcs_nodes.msgs.fields import (  # noqa: F401
    quat, stamp_ns, to_quat, to_stamp, to_vec3, vec3)
from adcs_nodes.core.samples import all_finite  # noqa: F401
