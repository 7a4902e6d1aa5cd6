# shellcheck shell=bash
# The environment the workspace is built in, for scripts/bootstrap.sh and scripts/sanitize.sh:
# source this file inside the subshell of the build, then call
# `colcon_environment VENV TOOLCHAIN ROOT`.
# colcon's own scripts and ament need the venv's tools first on PATH and its prefix in the
# ament/CMake search paths (rosidl finds the type supports through the ament index); the toolchain
# file drops the wheels' baked-in /opt/python include dirs; DDS discovery stays on loopback;
# ccache hashes paths under the clone ROOT (the venv's headers among them) relative to it, so
# another clone on the machine reuses its objects.
colcon_environment() {
  export VIRTUAL_ENV=$1
  export PATH=$1/bin:$PATH
  export AMENT_PREFIX_PATH=$1
  export CMAKE_PREFIX_PATH=$1
  export CMAKE_TOOLCHAIN_FILE=$2
  export ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST
  export CCACHE_BASEDIR=$3
  unset COLCON_PREFIX_PATH PYTHONPATH
}
