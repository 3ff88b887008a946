# shellcheck shell=bash
# Source this file to get the pip-based ROS 2 Jazzy environment of this workspace:
#   source tools/env.sh
# It is what `source /opt/ros/jazzy/setup.bash && source install/setup.bash` is on an
# apt install. Run `make setup` (or `make test`) once first.
_mecanum_ws="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
if [ ! -x "$_mecanum_ws/.venv/bin/python" ] || [ ! -d "$_mecanum_ws/install" ]; then
  echo "tools/env.sh: the workspace is not set up yet; run 'make setup' first" >&2
  return 1 2>/dev/null || exit 1
fi
export VIRTUAL_ENV="$_mecanum_ws/.venv"
export PATH="$VIRTUAL_ENV/bin:$PATH"
export PYTHONNOUSERSITE=1
# The ROS wheels are an ament prefix of their own (share/ament_index, lib/).
export AMENT_PREFIX_PATH="$VIRTUAL_ENV${AMENT_PREFIX_PATH:+:$AMENT_PREFIX_PATH}"
export CMAKE_PREFIX_PATH="$VIRTUAL_ENV${CMAKE_PREFIX_PATH:+:$CMAKE_PREFIX_PATH}"
# What the wheels' bootstrapper would do by re-executing every Python process.
_mecanum_libs="$VIRTUAL_ENV/lib"
for _d in "$VIRTUAL_ENV"/lib/python3.*/site-packages/ros_*.libs; do
  [ -d "$_d" ] && _mecanum_libs="$_mecanum_libs:$_d"
done
export LD_LIBRARY_PATH="$_mecanum_libs${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}"
export _ROS_WHEELS_BOOTSTRAP_COMPLETE=1
# Standard interfaces missing from PyPI (tf2_msgs), then this workspace.
# shellcheck disable=SC1091
[ -f "$VIRTUAL_ENV/ros_overlay/install/local_setup.bash" ] && \
  . "$VIRTUAL_ENV/ros_overlay/install/local_setup.bash"
# The ros2 command and ros2 launch, built from upstream by make setup (if it could).
# shellcheck disable=SC1091
[ -f "$VIRTUAL_ENV/ros2cli/install/local_setup.bash" ] && \
  . "$VIRTUAL_ENV/ros2cli/install/local_setup.bash"
# shellcheck disable=SC1091
. "$_mecanum_ws/install/local_setup.bash"
# Secure by default: discover only nodes on this machine unless the user chose otherwise.
export ROS_AUTOMATIC_DISCOVERY_RANGE="${ROS_AUTOMATIC_DISCOVERY_RANGE:-LOCALHOST}"
# Fast DDS announces every 0.5 s instead of 3 s: a node joining a running system finds it
# in 0-0.5 s, not 0-3 s (mecanum_bringup config/fastdds_discovery.xml; bench/discovery.py).
export FASTRTPS_DEFAULT_PROFILES_FILE="${FASTRTPS_DEFAULT_PROFILES_FILE:-$_mecanum_ws/install/mecanum_bringup/share/mecanum_bringup/config/fastdds_discovery.xml}"
unset _mecanum_ws _mecanum_libs _d
