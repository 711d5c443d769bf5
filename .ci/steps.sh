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
# apt_lock_hold: takes the same lock until the calling script ends (file descriptor 9), for a
# look at what is installed and the install that follows it, so that a list made before
# another script's install is not installed again. No apt_lock after it (it would wait for
# the lock its own script holds).
apt_lock_hold() { exec 9>"${TMPDIR:-/tmp}/servoarm-apt.lock"; flock 9; }
# idle_class: puts the calling shell (and what it starts from then on) into the machine's
# lowest CPU class, so that it runs only on cycles the foreground leaves idle. Nice or
# SCHED_IDLE alone does not do that when the kernel groups processes by session
# (autogroup): a background session then gets as much CPU as the foreground's. So, first
# choice, a cpu cgroup marked idle (cpu.idle, Linux >= 5.15; cgroup v2 or v1's cpu
# hierarchy, root only); else its session's autogroup at nice 19; and in every case
# SCHED_IDLE and nice 19 for the processes themselves. Sets SERVOARM_IDLE_CLASS to what it
# got. Call it in the shell that is to run idle, never inside $(...): a command substitution
# is a subshell of its own, which would get the class and exit, leaving its caller as it was.
idle_class() {
  local how="" g v2=/sys/fs/cgroup v1=/sys/fs/cgroup/cpu
  if [ -f "$v2/cgroup.controllers" ] && grep -qw cpu "$v2/cgroup.controllers" && [ -w "$v2" ]; then
    g=$v2/servoarm-idle
  elif [ -d "$v1" ] && [ -w "$v1" ]; then
    g=$v1/servoarm-idle
  else
    g=""
  fi
  if [ -n "$g" ] && mkdir -p "$g" 2>/dev/null; then
    if [ -f "$g/cpu.idle" ] && echo 1 > "$g/cpu.idle" 2>/dev/null && echo $BASHPID > "$g/cgroup.procs" 2>/dev/null; then
      how="cgroup ${g#/sys/fs/cgroup/} (cpu.idle)"
    elif [ -f "$g/cpu.shares" ] && echo 2 > "$g/cpu.shares" 2>/dev/null && echo $BASHPID > "$g/cgroup.procs" 2>/dev/null; then
      how="cgroup ${g#/sys/fs/cgroup/} (cpu.shares 2)"
    fi
  fi
  if [ -z "$how" ] && [ -w /proc/self/autogroup ] && echo 19 > /proc/$BASHPID/autogroup 2>/dev/null; then
    how="its session's autogroup at nice 19"
  fi
  renice -n 19 -p $BASHPID >/dev/null 2>&1 || true
  if chrt -i -p 0 $BASHPID >/dev/null 2>&1; then how="${how:+$how, }SCHED_IDLE"; fi
  SERVOARM_IDLE_CLASS=${how:-nice 19 only}
}
# ctest_slots CPUS: the `ctest -j` for CPUS processors. Each CPU is two CTest slots: a test that
# keeps a CPU busy asks for two, one that mostly waits on the clock for one, a vcan VM for three
# (PROCESSORS; the top CMakeLists.txt, "How CTest shares the machine").
ctest_slots() { echo $((2 * $1)); }
