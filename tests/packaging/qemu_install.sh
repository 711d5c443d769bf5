#!/usr/bin/env bash
# SPDX-License-Identifier: Apache-2.0
# The servoarm .deb installed the way a user installs it, on a Debian root of the
# package's architecture run under qemu-user (CTest packaging_install_qemu of a
# cross build; docs/building-and-testing.md "The package installed under qemu-user"):
#
#   1. a Debian root (debootstrap --foreign --variant=minbase, second stage in a
#      chroot under qemu-<arch>-static), cached as a tarball after its first build
#   2. apt-get update; apt-get install ./servoarm_*.deb: dpkg -i with its
#      dependencies from apt, the maintainer scripts run (service user, config mode)
#   3. the installed armfw --help / --config-keys and armctl kin fk / kin models run;
#      armctl's FK of the PUMA 560 zero pose against the closed form; with API=api the
#      installed armfw's network API: --api-reference, and armfw --sim --api-tcp 0
#      answering hello over TCP (protocol 1, six joints)
#   4. the shipped unit's ExecStart= line, with its EnvironmentFile and as its User=,
#      on the shipped /etc/servoarm/armfw.toml (bus.can = "sim", checked, not edited):
#      the pty console answers status / enable / movej / wait / status / disable
#      (driven by the installed armctl console --serial), then SIGTERM: exit 0
#   5. dpkg -r (binaries gone, conffiles kept), dpkg --purge (/etc/servoarm gone)
#
# usage: qemu_install.sh DEB_DIR DEB_ARCH WORK_DIR [API]
#   API: "api" when the package's armfw was built with the network API (the aarch64 tree's),
#        "no-api" (default) when not (the armhf tree's)
#        qemu_install.sh --root DEB_ARCH WORK_DIR
#   only step 1 into the cache (.ci/background runs it while the host tree builds); exit 0
#   when the cache has the root. The cache's lock file (<tarball>.lock) is held while a root
#   is bootstrapped, so a test that starts meanwhile waits for it (and says how long in
#   $SERVOARM_CI_TIMES as qemu-root-wait, when .ci/run set it), then unpacks the cached root.
# Environment:
#   SERVOARM_QEMU_ROOT_CACHE  folder of the cached roots (default /var/cache/servoarm/qemu-roots);
#                             "" = no cache (bootstrap every run)
#   SERVOARM_QEMU_SUITE       Debian suite of the root (default: the build machine's codename)
#   SERVOARM_QEMU_MIRROR      Debian mirror (default: the first one in the build machine's apt sources
#                             for that suite, else debootstrap's default)
# Exit status: 0 passed; 1 failed (the step is named); 77 skipped, the reason on
# stderr: not root, debootstrap or qemu-<arch>-static missing, no binfmt_misc
# entry for the architecture and none can be registered, the chroot cannot run
# the target's programs, or the mirror cannot be reached for the bootstrap.
set -euo pipefail
mode=install
if [ "${1:-}" = --root ]; then mode=root; shift; set -- "" "$@"; fi
deb_dir=${1?usage: qemu_install.sh DEB_DIR DEB_ARCH WORK_DIR [api|no-api] | --root DEB_ARCH WORK_DIR}
arch=${2:?usage: qemu_install.sh DEB_DIR DEB_ARCH WORK_DIR}
work=${3:?usage: qemu_install.sh DEB_DIR DEB_ARCH WORK_DIR}
api=${4:-no-api}
cache=${SERVOARM_QEMU_ROOT_CACHE-/var/cache/servoarm/qemu-roots}
t_start=$(date +%s)
say() { echo "qemu_install: $*"; }
skip() { echo "qemu_install: SKIPPED: $*" >&2; exit 77; }
fail() { echo "qemu_install: FAILED: $*" >&2; exit 1; }
lap() { say "$1: $(( $(date +%s) - t_lap )) s"; t_lap=$(date +%s); }
t_lap=$t_start

case "$arch" in
  arm64) qarch=aarch64 ;;
  armhf) qarch=arm ;;
  *) skip "no qemu-user mapping for Debian architecture '$arch' (arm64, armhf)" ;;
esac
[ "$(id -u)" -eq 0 ] || skip "needs root (debootstrap, chroot, mount, binfmt_misc); run as root"
command -v debootstrap >/dev/null || skip "debootstrap missing (apt-get install debootstrap; .ci/packages-cross)"
qemu_static=$(command -v "qemu-$qarch-static" || true)
[ -n "$qemu_static" ] || skip "qemu-$qarch-static missing (apt-get install qemu-user-static; .ci/packages-cross)"
if [ "$mode" = install ]; then
  debs=("$deb_dir"/servoarm_*_"$arch".deb)
  [ -f "${debs[0]}" ] || fail "no servoarm_*_$arch.deb in $deb_dir"
  [ ${#debs[@]} -eq 1 ] || fail "more than one servoarm_*_$arch.deb in $deb_dir: ${debs[*]}"
  deb=${debs[0]}
fi

suite=${SERVOARM_QEMU_SUITE:-$( . /etc/os-release 2>/dev/null; echo "${VERSION_CODENAME:-}")}
[ -n "$suite" ] || skip "no Debian codename in /etc/os-release; set SERVOARM_QEMU_SUITE"
# The build machine's mirror for that suite (deb822 .sources or one-line lists), not -security.
host_mirror() {
  python3 - "$suite" <<'PY' 2>/dev/null || true
import glob, sys
suite = sys.argv[1]
for path in sorted(glob.glob('/etc/apt/sources.list.d/*.sources')):
    for stanza in open(path).read().split('\n\n'):
        f = {}
        for line in stanza.splitlines():
            if ':' in line and not line.startswith('#'):
                k, v = line.split(':', 1)
                f[k.strip().lower()] = v.split()
        if 'deb' in f.get('types', []) and suite in f.get('suites', []) and f.get('uris'):
            print(f['uris'][0]); sys.exit(0)
for path in ['/etc/apt/sources.list'] + sorted(glob.glob('/etc/apt/sources.list.d/*.list')):
    try:
        lines = open(path).read().splitlines()
    except OSError:
        continue
    for line in lines:
        w = [x for x in line.split() if not x.startswith('[')]
        if len(w) >= 3 and w[0] == 'deb' and w[2] == suite:
            print(w[1]); sys.exit(0)
PY
}
mirror=${SERVOARM_QEMU_MIRROR:-$(host_mirror)}

# ---------------------------------------------------------------------------
# binfmt_misc: the kernel must hand the target's ELF files to qemu inside the
# chroot. An entry with the F flag (qemu-user-static's) keeps its interpreter
# open; one without it is looked up inside the root, so the static qemu is copied
# there to the entry's interpreter path.
bfm=/proc/sys/fs/binfmt_misc
[ -e $bfm/register ] || mount -t binfmt_misc binfmt_misc $bfm 2>/dev/null || true
[ -e $bfm/register ] || skip "binfmt_misc is not mounted and cannot be (mount -t binfmt_misc binfmt_misc $bfm)"
if [ ! -e "$bfm/qemu-$qarch" ] && [ -f "/usr/lib/binfmt.d/qemu-$qarch.conf" ]; then
  grep -v '^#' "/usr/lib/binfmt.d/qemu-$qarch.conf" >$bfm/register 2>/dev/null || true
fi
[ -e "$bfm/qemu-$qarch" ] || skip "no binfmt_misc entry qemu-$qarch and none could be registered (/usr/lib/binfmt.d/qemu-$qarch.conf)"
grep -qx enabled "$bfm/qemu-$qarch" || skip "binfmt_misc entry qemu-$qarch is disabled"
interp=$(sed -n 's/^interpreter //p' "$bfm/qemu-$qarch")
flags=$(sed -n 's/^flags: //p' "$bfm/qemu-$qarch")
say "binfmt_misc qemu-$qarch: interpreter $interp, flags '$flags'; $qemu_static"

# ---------------------------------------------------------------------------
# Mounts inside the root: /proc and a devpts of its own (the pty console), so the
# host's /dev is never bound in. Everything is unmounted before the root is removed,
# and the root is not removed while anything is still mounted under it.
root="$work/root"
armfw_pid=""
mounted() { awk -v r="$root" '$2 == r || index($2, r "/") == 1 { print $2 }' /proc/mounts; }
cleanup() {
  local rc=$?
  if [ -n "$armfw_pid" ]; then kill -KILL "$armfw_pid" 2>/dev/null || true; wait "$armfw_pid" 2>/dev/null || true; fi
  for m in $(mounted | sort -r); do umount "$m" 2>/dev/null || umount -l "$m" 2>/dev/null || true; done
  if [ -n "$(mounted)" ]; then
    echo "qemu_install: WARNING: still mounted under $root, left in place: $(mounted | tr '\n' ' ')" >&2
  elif [ "${SERVOARM_QEMU_KEEP_ROOT:-0}" != 1 ]; then
    rm -rf "$root"
  fi
  say "total $(( $(date +%s) - t_start )) s"
  exit $rc
}
trap cleanup EXIT
trap 'exit 143' TERM INT
mount_root() {
  mkdir -p "$root/proc" "$root/dev/pts"
  mount -t proc proc "$root/proc" || skip "cannot mount /proc in the root"
  mount -t devpts -o newinstance,ptmxmode=0666,mode=0620,gid=5 devpts "$root/dev/pts" ||
    skip "cannot mount a devpts instance in the root"
  rm -f "$root/dev/ptmx"; ln -s pts/ptmx "$root/dev/ptmx"
}
umount_root() { for m in $(mounted | sort -r); do umount "$m"; done; }
in_root() { chroot "$root" /usr/bin/env -i PATH=/usr/sbin:/usr/bin:/sbin:/bin HOME=/root LANG=C.UTF-8 \
            DEBIAN_FRONTEND=noninteractive "$@"; }
put_qemu() { if [[ $flags != *F* ]]; then mkdir -p "$root$(dirname "$interp")"; cp "$qemu_static" "$root$interp"; fi; }

# ---------------------------------------------------------------------------
# 1. The Debian root: from the cache, or bootstrapped (then cached).
[ -z "$(mounted)" ] || fail "something is still mounted under $root: $(mounted | tr '\n' ' ')"
rm -rf "$root"; mkdir -p "$root"
tarball=""
[ -z "$cache" ] || tarball="$cache/$suite-$arch-minbase.tar"
[ -n "$tarball" ] || [ "$mode" = install ] || skip "no root cache (SERVOARM_QEMU_ROOT_CACHE is empty): nothing to prepare"
if [ -n "$tarball" ]; then
  mkdir -p "$cache" || fail "cannot create the root cache $cache"
  exec 8>"$tarball.lock"
  t_w=$(date +%s)
  if ! flock -n 8; then
    say "waiting for the root being bootstrapped by another process ($tarball.lock)"
    flock 8
  fi
  waited=$(( $(date +%s) - t_w ))
  if [ "$mode" = install ] && [ -n "${SERVOARM_CI_TIMES:-}" ]; then echo "qemu-root-wait=$waited" >>"$SERVOARM_CI_TIMES"; fi
  [ "$waited" -eq 0 ] || lap "waited for the root's bootstrap"
  if [ "$mode" = root ] && [ -f "$tarball" ]; then say "the cache has the root: $tarball"; exit 0; fi
fi
if [ -n "$tarball" ] && [ -f "$tarball" ]; then
  tar -C "$root" -xf "$tarball" || fail "cannot unpack the cached root $tarball"
  put_qemu
  lap "root from the cache ($tarball)"
else
  say "bootstrapping $suite/$arch (minbase) from ${mirror:-the default mirror of debootstrap}"
  debootstrap --foreign --arch="$arch" --variant=minbase "$suite" "$root" ${mirror:+"$mirror"} >"$work/debootstrap1.log" 2>&1 ||
    skip "debootstrap --foreign failed (no network or mirror?): $(tail -n 2 "$work/debootstrap1.log" | tr '\n' ' ')"
  lap "debootstrap --foreign (download, unpack)"
  put_qemu
  chroot "$root" /bin/true 2>/dev/null || skip "the chroot cannot run $arch programs through binfmt_misc qemu-$qarch ($interp, flags '$flags')"
  chroot "$root" /debootstrap/debootstrap --second-stage >"$work/debootstrap2.log" 2>&1 ||
    fail "debootstrap --second-stage: $(tail -n 3 "$work/debootstrap2.log" | tr '\n' ' ')"
  lap "debootstrap --second-stage under qemu-$qarch"
  mount_root
  in_root apt-get update -qq >"$work/apt-update.log" 2>&1 || fail "apt-get update in the new root: $(tail -n 3 "$work/apt-update.log")"
  in_root apt-get clean
  umount_root
  lap "apt-get update in the root"
  if [ -n "$tarball" ]; then
    mkdir -p "$cache" && tar -C "$root" -cf "$tarball.tmp" . && mv "$tarball.tmp" "$tarball" &&
      say "root cached as $tarball" || say "WARNING: could not cache the root in $cache"
  fi
fi
[ -z "$tarball" ] || exec 8>&-  # (the cache's lock: the root is there, or this test bootstraps alone)
if [ "$mode" = root ]; then
  [ -f "$tarball" ] || fail "the root was bootstrapped but could not be cached in $cache"
  exit 0
fi
chroot "$root" /bin/true 2>/dev/null || skip "the chroot cannot run $arch programs through binfmt_misc qemu-$qarch ($interp, flags '$flags')"
mount_root

# ---------------------------------------------------------------------------
# 2. Install as a user does: apt-get install of the .deb file, dependencies from apt.
in_root apt-get update -qq >"$work/apt-update.log" 2>&1 || fail "apt-get update: $(tail -n 3 "$work/apt-update.log")"
cp "$deb" "$root/tmp/"
base=$(basename "$deb")
in_root apt-get install -y --no-install-recommends "/tmp/$base" >"$work/apt-install.log" 2>&1 ||
  fail "apt-get install ./$base: $(tail -n 5 "$work/apt-install.log")"
lap "apt-get update + install ./$base with its dependencies"
[ "$(in_root dpkg-query -W -f='${Status}' servoarm)" = "install ok installed" ] || fail "dpkg does not say servoarm is installed"
in_root getent passwd servoarm >/dev/null || fail "postinst did not create the servoarm user"
# (stat inside the root: the names are the root's /etc/passwd and /etc/group, not the host's)
conf_mode=$(in_root stat -c '%a %U:%G' /etc/servoarm/armfw.toml)
[ "$conf_mode" = "640 root:servoarm" ] || fail "/etc/servoarm/armfw.toml is $conf_mode, not 640 root:servoarm"
say "installed: $(in_root dpkg-query -W -f='${Package} ${Version} ${Architecture}' servoarm); user servoarm; config 640 root:servoarm"

# ---------------------------------------------------------------------------
# 3. The installed programs.
out=$(in_root /usr/bin/armfw --help 2>&1) || fail "armfw --help exit $?: $out"
[[ $out == usage:\ armfw* ]] || fail "armfw --help does not start with its usage line: ${out:0:200}"
in_root /usr/bin/armfw --config-keys >"$work/config-keys.txt" 2>&1 || fail "armfw --config-keys: $(tail -n 3 "$work/config-keys.txt")"
grep -q "bus.can" "$work/config-keys.txt" || fail "armfw --config-keys does not list bus.can"
out=$(in_root /usr/bin/armctl kin models 2>&1) || fail "armctl kin models exit $?: $out"
[[ $out == *puma560* ]] || fail "armctl kin models does not list puma560 (installed models): $out"
# PUMA 560 (kinematics/models/puma560.toml, standard DH) at q = 0: every theta 0, so the
# chain is Rx(-90) . [Tz(d2) Tx(a2)] . [Tx(a3) Rx(90)] . [Tz(d4) Rx(-90)] . Rx(90) . Tz(d6):
# x = a2 + a3 = 431.8 - 20.32, y = d2 = 149.09, z = d4 + d6 = 433.07 + 56.25 (mm), R = I.
out=$(in_root /usr/bin/armctl kin fk --robot puma560 --json 0 0 0 0 0 0 2>&1) || fail "armctl kin fk exit $?: $out"
python3 - "$out" <<'PY' || fail "armctl kin fk of the PUMA 560 zero pose: $out"
import json, sys
j = json.loads(sys.argv[1])
p, R = j["position"], j["rotation"]
assert j["length_unit"] == "mm" and len(p) == 3, j
assert all(abs(a - b) < 1e-4 for a, b in zip(p, [411.48, 149.09, 489.32])), p
assert all(abs(R[r][c] - (r == c)) < 1e-9 for r in range(3) for c in range(3)), R
PY
lap "armfw --help / --config-keys, armctl kin models / kin fk (x y z = 411.48 149.09 489.32 mm)"

# The network API of the installed armfw: its reference, then armfw --sim serving TCP on a
# free port (the root shares the build machine's network), and hello answered over it.
if [ "$api" = api ]; then
  out=$(in_root /usr/bin/armfw --api-reference 2>&1) || fail "armfw --api-reference exit $?: the installed armfw has no network API: ${out:0:200}"
  [[ $out == *'`hello`'* ]] || fail "armfw --api-reference does not list hello: ${out:0:200}"
  # (chroot itself in the background, not in_root: a function would run in a subshell, and
  # $! would be that shell, not armfw)
  chroot "$root" /usr/bin/env -i PATH=/usr/bin:/bin LANG=C.UTF-8 /usr/bin/armfw --sim --no-stdin --api-tcp 0 \
    </dev/null >"$work/api.out" 2>"$work/api.err" &
  armfw_pid=$!
  port=""
  for _ in $(seq 1 600); do
    port=$(sed -n 's/^armfw: api: .*TCP port \([0-9]*\).*/\1/p' "$work/api.err")
    [ -z "$port" ] || break
    kill -0 "$armfw_pid" 2>/dev/null || fail "armfw --sim --api-tcp 0 exited before serving: $(cat "$work/api.err")"
    sleep 0.1
  done
  [ -n "$port" ] || fail "armfw --sim --api-tcp 0 did not print its TCP port within 60 s: $(cat "$work/api.err")"
  python3 - "$port" <<'PY' || fail "hello over the installed armfw's API (TCP port $port): see above; armfw: $(tail -n 3 "$work/api.err")"
import json, socket, sys
s = socket.create_connection(("127.0.0.1", int(sys.argv[1])), timeout=60)
s.sendall(b'{"id":1,"cmd":"hello"}\n')
buf = b""
while b"\n" not in buf:
    chunk = s.recv(65536)
    assert chunk, "the server closed the connection before answering hello"
    buf += chunk
r = json.loads(buf.split(b"\n", 1)[0])
assert r.get("id") == 1 and r.get("ok") is True, r
assert r.get("protocol") == 1 and len(r.get("joints", [])) == 6, r
print("qemu_install: hello answered: protocol %d, %d joints" % (r["protocol"], len(r["joints"])))
PY
  kill -TERM "$armfw_pid"
  rc=0; wait "$armfw_pid" || rc=$?
  armfw_pid=""
  [ $rc -eq 0 ] || fail "armfw --sim --api-tcp 0 exit $rc after SIGTERM: $(tail -n 5 "$work/api.err")"
  lap "armfw --api-reference; armfw --sim --api-tcp $port answered hello over TCP; SIGTERM: exit 0"
fi

# ---------------------------------------------------------------------------
# 4. The service's command line, as systemd would start it (no systemd in the root).
unit="$root/lib/systemd/system/servoarm.service"
[ -f "$unit" ] || fail "no $unit"
exec_start=$(sed -n 's/^ExecStart=//p' "$unit")
user=$(sed -n 's/^User=//p' "$unit"); group=$(sed -n 's/^Group=//p' "$unit")
envfile=$(sed -n 's/^EnvironmentFile=-\{0,1\}//p' "$unit")
[ -n "$exec_start" ] && [ -n "$user" ] || fail "$unit has no ExecStart= or User="
# The shipped config drives the in-process virtual servos: the only change this test
# would make (bus.can = "sim") is already the default, so the file is used as shipped.
grep -Eq '^can = "sim"' "$root/etc/servoarm/armfw.toml" || fail "the shipped armfw.toml does not say can = \"sim\""
say "ExecStart=$exec_start (User=$user, EnvironmentFile=$envfile)"
# systemd expands $VAR from the EnvironmentFile and splits it into words: sh does the same.
chroot --userspec="$user:${group:-$user}" "$root" /usr/bin/env -i PATH=/usr/bin:/bin \
  /bin/sh -c "set -a; [ ! -r '$envfile' ] || . '$envfile'; set +a; exec $exec_start" \
  </dev/null >"$work/armfw.out" 2>"$work/armfw.err" &
armfw_pid=$!
pty=""
for _ in $(seq 1 600); do
  pty=$(sed -n 's/^armfw: console pty: //p' "$work/armfw.err")
  [ -z "$pty" ] || break
  kill -0 "$armfw_pid" 2>/dev/null || fail "armfw exited before opening its pty: $(cat "$work/armfw.err")"
  sleep 0.1
done
[ -n "$pty" ] || fail "armfw did not print its console pty within 60 s: $(cat "$work/armfw.err")"
lap "armfw started as $user, console on $pty"
in_root /usr/bin/armctl console --serial "$pty" --timeout 60 -c status -c enable -c 'movej 10 -20 30 0 15 0' -c wait \
  -c status -c disable >"$work/console.txt" 2>&1 || fail "armctl console (exit $?): $(cat "$work/console.txt")"
n_ok=$(grep -c '^ok' "$work/console.txt" || true)
[ "$n_ok" -eq 6 ] || fail "6 answers 'ok' expected, $n_ok: $(cat "$work/console.txt")"
! grep -q '^error' "$work/console.txt" || fail "an error answer: $(cat "$work/console.txt")"
grep -q '^ok enabled' "$work/console.txt" || fail "enable did not answer 'ok enabled': $(cat "$work/console.txt")"
kill -TERM "$armfw_pid"
rc=0; wait "$armfw_pid" || rc=$?
armfw_pid=""
[ $rc -eq 0 ] || fail "armfw exit $rc after SIGTERM: $(tail -n 5 "$work/armfw.err")"
grep -q '^armfw: exit:' "$work/armfw.err" || fail "armfw did not print its exit summary: $(tail -n 5 "$work/armfw.err")"
lap "console status/enable/movej/wait/status/disable answered ok; SIGTERM: exit 0"
sed 's/^/  console: /' "$work/console.txt"
grep -i 'warning' "$work/armfw.err" | sed 's/^/  armfw: /' || true

# ---------------------------------------------------------------------------
# 5. Removal: the binaries go, the conffiles stay until purge.
in_root dpkg -r servoarm >"$work/dpkg-r.log" 2>&1 || fail "dpkg -r servoarm: $(tail -n 5 "$work/dpkg-r.log")"
[ ! -e "$root/usr/bin/armfw" ] && [ ! -e "$root/usr/bin/armctl" ] || fail "dpkg -r left /usr/bin/armfw or armctl"
[ -f "$root/etc/servoarm/armfw.toml" ] || fail "dpkg -r removed the conffile /etc/servoarm/armfw.toml (only purge should)"
in_root dpkg --purge servoarm >"$work/dpkg-purge.log" 2>&1 || fail "dpkg --purge servoarm: $(tail -n 5 "$work/dpkg-purge.log")"
[ ! -e "$root/etc/servoarm" ] || fail "dpkg --purge left /etc/servoarm: $(ls -A "$root/etc/servoarm")"
in_root dpkg-query -W -f='${Status}' servoarm 2>/dev/null | grep -q 'not-installed' ||
  ! in_root dpkg-query -W servoarm >/dev/null 2>&1 || fail "dpkg still lists servoarm after purge"
lap "dpkg -r and dpkg --purge (maintainer scripts ok)"
say "PASSED"
