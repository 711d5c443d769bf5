# SPDX-License-Identifier: Apache-2.0
# shellcheck shell=bash
# Sourced by the .ci scripts: step_done NAME START records how long a step of a CI run
# took (seconds since START, a `date +%s` value) in $SERVOARM_CI_TIMES, which .ci/run
# sets and prints as one table at the end. Outside .ci/run it records nothing.
# apt_lock CMD...: runs an apt-get or dpkg command under one lock of the .ci scripts, since
# .ci/background installs the cross packages while other steps may install theirs.
step_done() {
  local s=$(( $(date +%s) - $2 ))
  if [ -n "${SERVOARM_CI_TIMES:-}" ]; then echo "$1=$s" >> "$SERVOARM_CI_TIMES"; fi
  return 0
}
apt_lock() { flock "${TMPDIR:-/tmp}/servoarm-apt.lock" "$@"; }
