#!/usr/bin/env bash
# Run a command inside the bootstrapped workspace: ros2_ws/setup.bash, ros2_ws/install sourced,
# run isolated to this machine. Usage: ros2_ws/run.sh adcs run scenarios/free_tumble.yaml
# The command runs in the caller's directory: relative paths mean what the caller means.
set -eo pipefail
WS="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
"$WS/bootstrap.sh"
# shellcheck disable=SC1091
source "$WS/setup.bash"
# shellcheck disable=SC1091
source "$WS/install/local_setup.bash"
export ROS_AUTOMATIC_DISCOVERY_RANGE="${ROS_AUTOMATIC_DISCOVERY_RANGE:-LOCALHOST}"
export PYTHONUNBUFFERED=1
export MPLBACKEND="${MPLBACKEND:-Agg}"
exec "$@"
