# shellcheck shell=bash
# Environment of the iceskate project. Use it from bash by sourcing:   . ./env.sh
#
# It activates .venv, sources the colcon workspace ros_ws/install, keeps DDS on loopback
# (the project's Fast DDS profile), gives this shell its own ROS_LOG_DIR and puts the
# packages' executable dirs (ros_ws/install/<pkg>/lib/<pkg>) on PATH.
# Needs `make setup` (scripts/bootstrap.sh) to have run; on failure it returns 1 and leaves the
# shell as it was.

_iceskate_root=$(cd "$(dirname "${BASH_SOURCE[0]:-$0}")" && pwd)

if [ ! -x "$_iceskate_root/.venv/bin/python" ] \
    || [ ! -f "$_iceskate_root/ros_ws/install/setup.bash" ]; then
  printf 'env.sh: %s is missing: run `make setup` first (in %s)\n' \
    "$([ -x "$_iceskate_root/.venv/bin/python" ] && echo ros_ws/install || echo .venv)" \
    "$_iceskate_root" >&2
  unset _iceskate_root
  # `return` when sourced; `exit` only ends the subshell of a script run as a program.
  return 1 2>/dev/null || exit 1
fi

# colcon's setup.bash (and venv's activate) are not `set -u` clean: relax -u while sourcing them.
case $- in *u*) _iceskate_had_u=1; set +u ;; *) _iceskate_had_u=0 ;; esac

# shellcheck disable=SC1091
. "$_iceskate_root/.venv/bin/activate"
# shellcheck disable=SC1091
. "$_iceskate_root/ros_ws/install/setup.bash"

# The venv is a ROS prefix too (share/ament_index of the wheels): keep it in the ament index path
# after the workspace, so ament_index_python finds std_msgs & co. as well as our packages.
case ":${AMENT_PREFIX_PATH:-}:" in
  *":$VIRTUAL_ENV:"*) ;;
  *) export AMENT_PREFIX_PATH="${AMENT_PREFIX_PATH:+$AMENT_PREFIX_PATH:}$VIRTUAL_ENV" ;;
esac

# DDS never leaves the machine (mandatory here): the project's Fast DDS profile puts every socket
# on 127.0.0.1 and discovers by unicast to 127.0.0.1; under it the discovery range is SUBNET, as
# rmw_fastrtps opens sockets on every interface in its LOCALHOST mode (docs/usage.md, "DDS
# stays on loopback"). Without the profile (not built yet), LOCALHOST.
_iceskate_dds="$_iceskate_root/ros_ws/install/iceskate_sim/share/iceskate_sim/config/fastdds_loopback.xml"
if [ -f "$_iceskate_dds" ]; then
  export FASTRTPS_DEFAULT_PROFILES_FILE="$_iceskate_dds" FASTDDS_DEFAULT_PROFILES_FILE="$_iceskate_dds"
  export ROS_AUTOMATIC_DISCOVERY_RANGE=SUBNET
else
  export ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST
fi
# Ray (sweep --ray) never reports usage statistics.
export RAY_USAGE_STATS_ENABLED=0

# One ROS log directory per shell (every ROS process writes a log file; rclpy.init fails when the
# directory cannot be created).
export ROS_LOG_DIR="${TMPDIR:-/tmp}/iceskate-ros-log-$(id -u)-$$"
mkdir -p "$ROS_LOG_DIR"

# Executables of our packages (what `ros2 run <pkg> <exe>` would start) are runnable by name.
for _iceskate_dir in "$_iceskate_root"/ros_ws/install/*/lib/*; do
  _iceskate_pkg=$(basename "$(dirname "$(dirname "$_iceskate_dir")")")
  if [ -d "$_iceskate_dir" ] && [ "$(basename "$_iceskate_dir")" = "$_iceskate_pkg" ]; then
    case ":$PATH:" in
      *":$_iceskate_dir:"*) ;;
      *) PATH="$_iceskate_dir:$PATH" ;;
    esac
  fi
done
export PATH

if [ "$_iceskate_had_u" = 1 ]; then set -u; fi
unset _iceskate_root _iceskate_had_u _iceskate_dir _iceskate_pkg _iceskate_dds
return 0 2>/dev/null || true
