#!/usr/bin/env bash
# Bootstrap the ADCS workspace on a machine with only Python 3.11 (no ROS install needed).
#
#   1. a virtual environment in ros2_ws/.venv with the pinned ROS 2 wheels from PyPI
#      (ros2_ws/requirements.txt),
#   2. the known path pitfall of those wheels fixed: some installed share/**/*.cmake files carry
#      the wheel builder's Python and numpy include paths; they are rewritten to this
#      interpreter's sysconfig include dir and numpy.get_include(),
#   3. `colcon build --symlink-install` of adcs_msgs, adcs_nodes and sim_node into
#      ros2_ws/install, with -DPython3_EXECUTABLE set; before it, the fallback interface
#      package ros2_ws/extra/tf2_msgs (the upstream TFMessage definition, same type hash) into
#      ros2_ws/.venv/underlay, only when the environment has no tf2_msgs (the PyPI wheels do
#      not ship it; a ROS 2 install does),
#   4. the `adcs` command in the venv,
#   5. numba's kernel cache filled once, serially (sim_node.tools.warm_kernels; not with
#      NUMBA_DISABLE_JIT=1),
#   6. the project's own modules byte-compiled (__pycache__/*.pyc), also when the environment
#      says PYTHONDONTWRITEBYTECODE.
#
# Each step is skipped when its inputs did not change (stamp files in .venv/), so a second run
# takes about a second. Then `source ros2_ws/setup.bash` gives a shell this environment. On a
# machine with ROS 2 installed, you do not need this script: source
# /opt/ros/<distro>/setup.bash, then `colcon build` in ros2_ws.
set -euo pipefail

WS="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
VENV="$WS/.venv"
PYTHON_BIN="${ADCS_PYTHON:-}"
if [ -z "$PYTHON_BIN" ]; then
    for cand in python3.11 python3; do
        if command -v "$cand" >/dev/null 2>&1; then PYTHON_BIN="$cand"; break; fi
    done
fi
if [ -z "$PYTHON_BIN" ]; then
    echo "bootstrap: no python3.11 found; install Python 3.11 (apt-get install python3.11 python3.11-venv)" >&2
    exit 1
fi
ver="$("$PYTHON_BIN" -c 'import sys; print("%d.%d" % sys.version_info[:2])')"
if [ "$ver" != "3.11" ]; then
    echo "bootstrap: the pinned ROS 2 wheels need CPython 3.11, found $PYTHON_BIN = $ver" >&2
    echo "           (set ADCS_PYTHON=/path/to/python3.11)" >&2
    exit 1
fi

say() { printf '[bootstrap] %s\n' "$*"; }

# one bootstrap at a time (parallel `make` targets, test helpers): the others wait here
mkdir -p "$WS/log"
exec 9> "$WS/log/.bootstrap.lock"
flock 9

hash_of() { cat "$@" 2>/dev/null | sha256sum | cut -d' ' -f1; }

# 1. virtual environment + pinned wheels
if [ ! -x "$VENV/bin/python" ]; then
    say "creating virtual environment $VENV"
    "$PYTHON_BIN" -m venv "$VENV"
fi
# the venv is the wheels' ROS 2 prefix (ros2_ws/setup.bash): colcon wants a local_setup there
[ -f "$VENV/local_setup.sh" ] || echo '# the PyPI wheels: see ros2_ws/setup.bash' > "$VENV/local_setup.sh"
req_hash="$(hash_of "$WS/requirements.txt")"
if [ "$(cat "$VENV/.requirements.sha256" 2>/dev/null)" != "$req_hash" ]; then
    say "installing pinned requirements (first run: about a minute)"
    mkdir -p "$WS/log"
    if ! { "$VENV/bin/python" -m pip install --disable-pip-version-check -q --upgrade "pip==26.3" &&
           "$VENV/bin/python" -m pip install --disable-pip-version-check -q -r "$WS/requirements.txt"; } \
            > "$WS/log/pip-install.out" 2>&1; then
        grep -v 'is ignored: it is neither' "$WS/log/pip-install.out" >&2
        echo "bootstrap: pip install failed (log: ros2_ws/log/pip-install.out)" >&2
        exit 1
    fi
    rm -f "$VENV/.cmake-fixed" "$VENV/.build.sha256"
    echo "$req_hash" > "$VENV/.requirements.sha256"
fi

# 2. the wheels' cmake files name the wheel builder's include dirs: point them at ours
if [ ! -f "$VENV/.cmake-fixed" ]; then
    "$VENV/bin/python" - "$VENV" <<'PY'
import pathlib, re, sys, sysconfig
import numpy
venv = pathlib.Path(sys.argv[1])
py_inc = sysconfig.get_paths()["include"]
np_inc = numpy.get_include()
pat_py = re.compile(r"/opt/python/[^/;\"\s]+/include/python3\.\d+")
pat_np = re.compile(r"/opt/python/[^;\"\s]*?/site-packages/numpy/_?core/include")
n = 0
for path in venv.rglob("*.cmake"):
    text = path.read_text(errors="surrogateescape")
    new = pat_np.sub(np_inc, pat_py.sub(py_inc, text))
    if new != text:
        path.write_text(new, errors="surrogateescape")
        n += 1
print(f"[bootstrap] rewrote include paths in {n} cmake files")
PY
    touch "$VENV/.cmake-fixed"
fi

# 3. colcon build (inputs: package manifests, build files, interface definitions)
export AMENT_PREFIX_PATH="$VENV${AMENT_PREFIX_PATH:+:$AMENT_PREFIX_PATH}"
export CMAKE_PREFIX_PATH="$VENV${CMAKE_PREFIX_PATH:+:$CMAKE_PREFIX_PATH}"
cd "$WS"
# fallback packages (ros2_ws/extra, COLCON_IGNOREd for a plain `colcon build`): built into the
# underlay .venv/underlay (part of the environment ros2_ws/setup.bash gives), only when no
# other prefix (the venv, or a sourced ROS 2 install) provides them
UNDERLAY="$VENV/underlay"
installed_pkg() {
    local prefix
    local IFS=:
    for prefix in $AMENT_PREFIX_PATH; do
        case "$prefix" in "$WS/install"*|"$UNDERLAY"*) continue ;; esac
        [ -e "$prefix/share/ament_index/resource_index/packages/$1" ] && return 0
    done
    return 1
}
rm -rf install/tf2_msgs build/tf2_msgs       # where an older bootstrap built the fallback
for pkg in tf2_msgs; do
    if installed_pkg "$pkg"; then
        rm -rf "${UNDERLAY:?}/$pkg"            # a former fallback must not shadow the real one
    elif [ ! -f "$UNDERLAY/$pkg/share/$pkg/package.bash" ]; then
        say "building the fallback $pkg into $UNDERLAY"
        if ! ( source "$VENV/bin/activate"
               colcon --log-base log build --base-paths "extra/$pkg" --build-base build/underlay \
                   --install-base "$UNDERLAY" --event-handlers console_cohesion- status- \
                   --cmake-args -DPython3_EXECUTABLE="$VENV/bin/python" -DBUILD_TESTING=OFF
             ) > "$WS/log/colcon-underlay.out" 2>&1 < /dev/null; then
            cat "$WS/log/colcon-underlay.out" >&2
            echo "bootstrap: building the fallback $pkg failed" >&2
            exit 1
        fi
    fi
done
# shellcheck disable=SC1091
[ -f "$UNDERLAY/local_setup.bash" ] && { set +u; source "$UNDERLAY/local_setup.bash"; set -u; }
build_inputs=$(find -L src -maxdepth 3 \( -name package.xml -o -name CMakeLists.txt \
    -o -name setup.py -o -name setup.cfg -o -name '*.msg' -o -name '*.srv' -o -name '*.action' \) \
    | sort)
# installed data files (symlinked one by one): a new or removed one needs a build, an edit does not
data_names=$(find -L src -maxdepth 3 \( -name '*.launch.py' -o -path '*/scenarios/*.yaml' \) \
    | sort)
build_hash="$( (echo "$build_inputs"; echo "$data_names"; hash_of $build_inputs) | sha256sum | cut -d' ' -f1)"
if [ "$(cat "$VENV/.build.sha256" 2>/dev/null)" != "$build_hash" ] || [ ! -f install/local_setup.bash ]; then
    say "colcon build (src)"
    # shellcheck disable=SC1091
    source "$VENV/bin/activate"
    if ! colcon --log-base log build --symlink-install --base-paths src \
            --event-handlers console_cohesion- summary+ status- \
            --cmake-args -DPython3_EXECUTABLE="$VENV/bin/python" -DBUILD_TESTING=OFF \
            > "$WS/log/colcon-build.out" 2>&1 < /dev/null; then
        cat "$WS/log/colcon-build.out" >&2
        echo "bootstrap: colcon build failed (full log above and in ros2_ws/log/)" >&2
        exit 1
    fi
    echo "$build_hash" > "$VENV/.build.sha256"
fi

# 4. the `adcs` command in the venv (the colcon install puts console scripts under
#    install/adcs_nodes/lib/adcs_nodes, which is what `ros2 run` uses; users want `adcs` on PATH)
if [ ! -x "$VENV/bin/adcs" ]; then
    cat > "$VENV/bin/adcs" <<'SH'
#!/usr/bin/env bash
exec python -m adcs_nodes.tools.cli "$@"
SH
    chmod +x "$VENV/bin/adcs"
fi

# 5. numba's on-disk kernel cache (__pycache__/*.nbi, *.nbc next to the core sources), filled
#    here once, serially, under the lock: node processes started together then only read it.
#    Processes that compile and save signatures of one kernel at the same time can leave an
#    index pointing at another process's object code (numba #4807, #10128; a node SIGSEGV at
#    start-up in a fresh-clone CI run). numba 0.68 keys a cache entry on the source file's
#    contents, so the stamp hashes the kernel sources (and the scenarios, whose parameters
#    reach the kernels), the numba version, NUMBA_CACHE_DIR and the index files that exist.
warm_stamp() {
    local dirs=("$WS/src/adcs_nodes/adcs_nodes/core" "$WS/src/sim_node/sim_node/models")
    {
        ls -d "$VENV"/lib/python3*/site-packages/numba-*.dist-info
        echo "NUMBA_CACHE_DIR=${NUMBA_CACHE_DIR:-}"
        find -L "${dirs[@]}" "$WS/src/adcs_nodes/scenarios" -type f \
            \( -name '*.py' -o -name '*.yaml' \) -print0 | sort -z | xargs -0 sha256sum
        find -L "${dirs[@]}" -name '*.nbi' | sort
    } 2>&1 | sha256sum | cut -d' ' -f1
}
if [ "${NUMBA_DISABLE_JIT:-0}" = 0 ] && [ "$(cat "$VENV/.numba-warm.sha256" 2>/dev/null)" != "$(warm_stamp)" ]; then
    say "warming numba kernel cache"
    # shellcheck disable=SC1091
    if ! ( set +u; source "$WS/setup.bash"; source "$WS/install/local_setup.bash"
           exec python -m sim_node.tools.warm_kernels ) > "$WS/log/warm-kernels.out" 2>&1 < /dev/null; then
        # not fatal: the nodes then compile what they need themselves (tried again next time)
        cat "$WS/log/warm-kernels.out" >&2
        echo "bootstrap: WARNING: numba kernel warm-up failed (log: ros2_ws/log/warm-kernels.out)" >&2
    else
        say "$(tail -n 1 "$WS/log/warm-kernels.out")"
        warm_stamp > "$VENV/.numba-warm.sha256"
    fi
fi

# 6. byte-compiled project modules. A run starts 8-15 Python processes that import adcs_nodes
#    and sim_node; without .pyc files each compiles their sources again (about 0.35 s of CPU a
#    process, 20 % of a short graph run's CPU), which is what happens when the environment
#    sets PYTHONDONTWRITEBYTECODE (Python then never writes them itself). compileall writes
#    them regardless, and only for sources newer than their .pyc; the stamp skips the walk
#    when no source changed since the last time.
pyc_stamp="$VENV/.pyc.stamp"
if [ ! -f "$pyc_stamp" ] || [ -n "$(find -L "$WS/src/adcs_nodes/adcs_nodes" "$WS/src/sim_node/sim_node" \
        -name '*.py' -newer "$pyc_stamp" -print -quit)" ]; then
    touch "$pyc_stamp.new"
    if "$VENV/bin/python" -m compileall -q -j 0 "$WS/src/adcs_nodes/adcs_nodes" \
            "$WS/src/sim_node/sim_node" > "$WS/log/compileall.out" 2>&1; then
        mv "$pyc_stamp.new" "$pyc_stamp"
    else   # not fatal: a syntax error shows where the module is imported
        rm -f "$pyc_stamp.new"
    fi
fi
