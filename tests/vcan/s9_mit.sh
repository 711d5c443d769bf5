# SPDX-License-Identifier: Apache-2.0
# Scenario 9: MIT-mode motors on SocketCAN. armsim --mit serves six Damiao DM-J4340 (ids 1-6,
# master ids 0x11-0x16) and a seventh motor in position-velocity mode (id 7) on $CAN_IF, in CAN
# FD when the interface takes it (mtu 72), else classic; armfw (bus.can = $CAN_IF, console over
# ISO-TP) drives the six as the puma560's joints (without gravity: the virtual motors carry no
# load, and free-drive sends the model's gravity torque). Checked from candump, byte by byte, on
# the host (s9_mit.host-check):
#   - bring-up: each motor's CTRL_MODE read, written to 1 (MIT) on motor 3 (powered up in
#     position-velocity mode), its CAN timeout written to bus.heartbeat_timeout_ms (0x7FF
#     register frames), then the enable frame FF..FC on its id;
#   - the MIT frames of a movej: on ids 1-6 only, kp / kd as configured, every position decoded
#     within the joint's limits, the last one at the movej's goal;
#   - free-drive: the frames go out with kp = kd = 0 and the torque code nearest 0 (no gravity,
#     no damping): 2048 of 0..4095, +0.0068 N m on +-28 N m, half a code; the virtual motor has
#     viscous damping (0.05 N m s/rad) and no static friction, so that half code turns it at
#     0.137 rad/s (7.8 deg/s): the joints creep no faster than 9 deg/s (a real motor's friction
#     holds it), no runaway;
#   - armfw killed: the motors' own watchdog disables them (error 0xD, communication lost), seen
#     by the drive doctor, which finds the six motors and the one in the wrong mode;
#   - before armfw starts, `armctl drives check` of the same configuration: every joint ok, the
#     motor in position-velocity mode a note, motor 7 named as no joint's; on CAN FD also the
#     check and a scan in classic CAN, the motors' stand-in for another bitrate: not seen, said so.
. "$SCENARIO_DIR/lib.sh"
. "$SCENARIO_DIR/s5_lib.sh"
need candump isotpsend isotprecv isotpsniffer armsim armfw armctl od mkfifo

fd=0
if ip link set dev "$CAN_IF" down && ip link set dev "$CAN_IF" mtu 72 && ip link set dev "$CAN_IF" up; then fd=1
else ip link set dev "$CAN_IF" up; fi
if [ "$fd" = 1 ]; then log "CAN FD on $CAN_IF (mtu 72)"; mit_fd=--mit-fd fd_key=true scan_fd=--fd
else log "classic CAN on $CAN_IF (no CAN FD)"; mit_fd= fd_key=false scan_fd=; fi

# puma560 without gravity (same kinematics, limits and inertias)
{ echo 'gravity = [0, 0, 0]'; grep -v '^gravity' "$SCENARIO_DIR/puma560.toml"; } >"$OUT_DIR/puma560_nog.toml"
# The motors' CAN timeout is bus.heartbeat_timeout_ms: 1 s, longer than the VM's worst stalls
# (a busy host starves the emulated CPUs for up to ~0.6 s), so a stall does not trip it.
hb_timeout_ms=1000
write_armfw_config "$OUT_DIR/armfw.toml" --own-drives
sed -i "s|^robot = .*|robot = \"$OUT_DIR/puma560_nog.toml\"|" "$OUT_DIR/armfw.toml"
# following error limit 90 deg: a starved VM (armsim or armfw descheduled for a few hundred ms
# during the movej) lets a joint fall 20 deg behind; the scenario is about the frames, the limit
# has its own tests (fw_mit_arm)
sed -i "s|^following_error_deg = .*|following_error_deg = 90|" "$OUT_DIR/armfw.toml"
# free-drive without gravity and without virtual damping (the virtual motors' inertia is not the
# model's: a damping torque sized for the puma's links would not be stable on them): torque 0
printf '[dynamics]\nfreedrive = true\nfreedrive_damping = 0\n' >>"$OUT_DIR/armfw.toml"
for j in 1 2 3 4 5 6; do
  printf '[[drive]]\nfamily = "damiao"\nmotor = "DM-J4340"\nnode = %d\ncan_fd = %s\nmit_kp = 60\nmit_kd = 2\nhoming.method = "absolute"\n' \
    "$j" "$fd_key" >>"$OUT_DIR/armfw.toml"
done

start_candump all -r 4194304 "$CAN_IF,000:F00,7FF:7FF"   # ids 0x000-0x0FF (MIT commands and answers) and 0x7FF
# motor 3 powers up in position-velocity mode (armfw switches it to MIT); motor 7, in the same
# mode, is no joint's (the drive doctor reports it)
start_armsim armsim --nodes none --mit DM-J4340:1 --mit DM-J4340:2 --mit DM-J4340:3 --mit DM-J4340:4 \
  --mit DM-J4340:5 --mit DM-J4340:6 --mit DM-J8006:7 --mit-mode 3:2 --mit-mode 7:2 $mit_fd
# the drive doctor before armfw runs: the configuration against the bus (exit 0; motor 3's mode
# and the CAN timeouts are notes, armfw sets them; motor 7 is no joint's), and, on CAN FD, the
# configuration and a scan in the other frame format (what a motor at another bitrate looks like:
# not seen, said so)
csrc=0
armctl drives check --config "$OUT_DIR/armfw.toml" --timeout 300 >"$OUT_DIR/check.txt" 2>&1 || csrc=$?
if [ "$fd" = 1 ]; then
  sed 's/^can_fd = true/can_fd = false/' "$OUT_DIR/armfw.toml" >"$OUT_DIR/armfw_classic.toml"
  wcrc=0
  armctl drives check --config "$OUT_DIR/armfw_classic.toml" --timeout 300 >"$OUT_DIR/check_classic.txt" 2>&1 || wcrc=$?
  wsrc=0
  armctl drives scan --iface "$CAN_IF" --last 16 --timeout 300 >"$OUT_DIR/scan_classic.txt" 2>&1 || wsrc=$?
fi
start_isotprecv
log "armfw: ${rate_hz} Hz, CAN timeout ${hb_timeout_ms} ms"
t_armfw=$(date +%s.%N)
start_armfw "$OUT_DIR/armfw.toml"
first_contact
# each step's answer must be ok; else armfw's log says why and the scenario stops there
step() {
  _s_a=$(isotp_ask "$1" "${2:-30}")
  case $_s_a in
    ok*) pass "$1: $_s_a" ;;
    *) check_fail "$1: want ok, got '$_s_a'"; isotp_ask status 10; echo "--- armfw.log"; tail -n 30 "$OUT_DIR/armfw.log"
       kill -KILL "$ARMFW_PID" "$ARMSIM_PID" 2>/dev/null; stop_isotprecv; stop_candump all; finish ;;
  esac
}
step enable 60
step status
goal="20 -30 40 15 -20 30"
step "movej $goal speed=50"
step wait 60
step "freedrive on"
sleep 1
step status
log "kill -KILL armfw (the motors' watchdog must stop them)"
kill -KILL "$ARMFW_PID"; wait "$ARMFW_PID" 2>/dev/null
stop_isotprecv
sleep 1
src=0
armctl drives scan --iface "$CAN_IF" $scan_fd --last 16 --timeout 300 >"$OUT_DIR/scan.txt" 2>&1 || src=$?
stop_armsim
stop_candump all
cat "$OUT_DIR/scan.txt"
ip link set dev "$CAN_IF" down; ip link set dev "$CAN_IF" mtu 16; ip link set dev "$CAN_IF" up

# the frames and the drive doctor's output are judged on the host (s9_mit.host-check)
can_if=$CAN_IF
to_host fd hb_timeout_ms t_armfw goal src csrc wcrc wsrc can_if
finish
