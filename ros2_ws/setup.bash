# The ROS 2 environment of this project's venv (the PyPI wheels): what
# `source /opt/ros/<distro>/setup.bash` is on a machine with ROS 2 installed. After `make build`:
#   source <repo>/ros2_ws/setup.bash                 # bash
#   colcon build                                     # in any workspace (ros2_ws, or your own)
#   source install/local_setup.bash
# It activates ros2_ws/.venv, puts the venv (where the wheels install their ament index and
# CMake configs) on AMENT_PREFIX_PATH and CMAKE_PREFIX_PATH, and sources the underlay
# .venv/underlay (tf2_msgs, which the wheels lack: ros2_ws/extra). ros2_ws/run.sh sources it.
_adcs_ws="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
if [ ! -x "$_adcs_ws/.venv/bin/python" ]; then
    echo "setup.bash: $_adcs_ws/.venv does not exist: run 'make build' first" >&2
    unset _adcs_ws
    return 1
fi
# shellcheck disable=SC1091
source "$_adcs_ws/.venv/bin/activate"
case ":${AMENT_PREFIX_PATH:-}:" in *":$VIRTUAL_ENV:"*) ;; *)
    export AMENT_PREFIX_PATH="$VIRTUAL_ENV${AMENT_PREFIX_PATH:+:$AMENT_PREFIX_PATH}" ;; esac
case ":${CMAKE_PREFIX_PATH:-}:" in *":$VIRTUAL_ENV:"*) ;; *)
    export CMAKE_PREFIX_PATH="$VIRTUAL_ENV${CMAKE_PREFIX_PATH:+:$CMAKE_PREFIX_PATH}" ;; esac
if [ -f "$VIRTUAL_ENV/underlay/local_setup.bash" ]; then
    # shellcheck disable=SC1091
    source "$VIRTUAL_ENV/underlay/local_setup.bash"
fi
unset _adcs_ws
