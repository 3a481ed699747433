"""The launcher behind ``adcs run``, by concern: run isolation and the DDS environment
(:mod:`.isolation`), the node processes (:mod:`.processes`), the rclpy monitor
(:mod:`.monitor`), the lifecycle client (:mod:`.lifecycle`), self-healing (:mod:`.healing`),
supervision (:mod:`.supervise`: :class:`Launcher`) and the result text (:mod:`.result`)."""
from adcs_nodes.tools.run.launcher.isolation import (DDS_ENV_KEYS, FASTDDS_PROFILES,  # noqa: F401
                                                     RUNS_DIR, LaunchError, acquire_domain,
                                                     child_env, profile_env, use_dds_env)
from adcs_nodes.tools.run.launcher.result import (EXIT_DEGRADED, RunResult,  # noqa: F401
                                                  external_devices)
from adcs_nodes.tools.run.launcher.supervise import Launcher, check_rate, pace  # noqa: F401
