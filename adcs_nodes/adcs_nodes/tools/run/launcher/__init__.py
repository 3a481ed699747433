"""The launcher behind ``adcs run``, a module per concern; its public names."""
from adcs_nodes.tools.run.launcher.isolation import (DDS_ENV_KEYS, FASTDDS_PROFILES,  # noqa: F401
                                                     RUNS_DIR, LaunchError, acquire_domain,
                                                     child_env, profile_env, use_dds_env)
from adcs_nodes.tools.run.launcher.result import (EXIT_DEGRADED, RunResult,  # noqa: F401
                                                  external_devices)
from adcs_nodes.tools.run.launcher.supervise import Launcher, check_rate, pace  # noqa: F401
