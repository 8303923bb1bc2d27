#!/bin/sh
# Install ROS 2 Jazzy's launch and launch_ros (no pip wheels) into a private folder, to run
# launch/pipeline.launch.py and its tests (test/test_launch.py, test_package_build.py) in
# the pip environment: launch, launch_ros and osrf_pycommon with pip --target, and the
# composition_interfaces messages (launch_ros.actions imports them) built with the wheels'
# rosidl generators, as tools/build_tf2_msgs.sh builds tf2_msgs (run that first: it installs
# the generators into VENV; needs cmake and a C++ compiler). Nothing goes into VENV.
# Usage: tools/install_launch.sh TARGET [VENV]      (VENV default .venv)
# Sources: the jazzy branches of ros2/launch, ros2/launch_ros and ros2/rcl_interfaces,
# cloned from GitHub, or local clones (bare or not) given as LAUNCH_GIT, LAUNCH_ROS_GIT,
# RCL_INTERFACES_GIT. Then:
#   PYTHONPATH=TARGET/python:TARGET/prefix/lib/python3.X/site-packages pytest test/test_launch.py
set -eu
mkdir -p "$1"
TARGET=$(cd "$1" && pwd)
VENV=$(cd "${2:-.venv}" && pwd)
PY="$VENV/bin/python"
unset _ROS_WHEELS_BOOTSTRAP_COMPLETE
SRC="$TARGET/src"
rm -rf "$SRC" "$TARGET/python" "$TARGET/prefix" "$TARGET/build"
mkdir -p "$SRC"
fetch() {   # fetch REPO_OR_URL FOLDER...: the jazzy branch's FOLDERs into $SRC
    repo=$1; shift
    case $repo in
        http*) git clone -q --depth 1 --branch jazzy "$repo" "$SRC/clone"
               repo="$SRC/clone" ;;
    esac
    git -C "$repo" archive jazzy "$@" | tar -x -C "$SRC"
    rm -rf "$SRC/clone"
}
fetch "${LAUNCH_GIT:-https://github.com/ros2/launch}" launch
fetch "${LAUNCH_ROS_GIT:-https://github.com/ros2/launch_ros}" launch_ros
fetch "${RCL_INTERFACES_GIT:-https://github.com/ros2/rcl_interfaces}" composition_interfaces
"$PY" -m pip install --disable-pip-version-check -q --no-deps --target "$TARGET/python" \
    "$SRC/launch" "$SRC/launch_ros" osrf_pycommon==2.0.2
BUILD="$TARGET/build"
mkdir -p "$BUILD"
export AMENT_PREFIX_PATH="$VENV" CMAKE_PREFIX_PATH="$VENV" PATH="$VENV/bin:$PATH"
cmake -S "$SRC/composition_interfaces" -B "$BUILD" -DCMAKE_INSTALL_PREFIX="$TARGET/prefix" \
    -DPython3_EXECUTABLE="$PY" -DPYTHON_EXECUTABLE="$PY" -DBUILD_TESTING=OFF \
    -DCMAKE_INSTALL_RPATH="$TARGET/prefix/lib;$VENV/lib" -DCMAKE_INSTALL_RPATH_USE_LINK_PATH=ON \
    -DCMAKE_BUILD_TYPE=Release > "$BUILD/cmake.log" 2>&1 || { tail -40 "$BUILD/cmake.log"; exit 1; }
cmake --build "$BUILD" -j2 > "$BUILD/build.log" 2>&1 || { tail -40 "$BUILD/build.log"; exit 1; }
cmake --install "$BUILD" > "$BUILD/install.log" 2>&1 || { tail -20 "$BUILD/install.log"; exit 1; }
SITE=$(echo "$TARGET"/prefix/lib/python3*/site-packages)
PYTHONPATH="$TARGET/python:$SITE" "$PY" -c "import launch_ros.actions
from importlib.metadata import version as v
print('launch', v('launch'), 'launch_ros', v('launch_ros'), 'osrf_pycommon', v('osrf_pycommon'))"
echo "PYTHONPATH=$TARGET/python:$SITE"
