#!/usr/bin/env bash
# Proves the SocketCAN path on a real Linux kernel: boots a Debian kernel under QEMU (TCG,
# no KVM needed) with the vcan module, runs the simulated PA10 controller (`pa10 sim --can
# vcan0`) and the daemon (`pa10d`, socketcan backend) on vcan0, and checks:
#   1. three joint moves with `pa10 move joints --wait` end where they were sent;
#   2. a candump capture of the traffic decodes with docs/pa10.dbc (cantools) to the same
#      values as the codec's (`pa10 sim decode`);
#   3. killing the simulator makes the daemon stop on its feedback timeout, visible in status;
# then the CAN FD variant on vcan1 (MTU 72; bus.fd: true, bus.data_bitrate: 5000000):
#   4. pa10d refuses an FD configuration on vcan0 set to MTU 16 (classic only), naming the MTU;
#   5. two joint moves on FD land, status says framing fd;
#   6. the FD capture (COMMAND_FD / FEEDBACK_FD as candump's ID##1 lines) decodes with
#      docs/pa10-fd.dbc (cantools) to the codec's values.
# Fails loudly with the VM's console. Downloads (the kernel package) are cached in
# $PA10_VCAN_CACHE (default ~/.cache/pa10-vcan). Needs root for apt-get only when the
# packages are missing. Usage: tests/vcan/run.sh [--prepare]
# (--prepare: only the installs and the kernel's download, then exit - CI starts it at the
# beginning, in the background, so a fresh machine's downloads overlap the builds)
set -euo pipefail
root=$(cd "$(dirname "$0")/../.." && pwd)
cache=${PA10_VCAN_CACHE:-$HOME/.cache/pa10-vcan}
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
mkdir -p "$cache"

need=()
command -v qemu-system-x86_64 >/dev/null || need+=(qemu-system-x86)
[ -x /bin/busybox ] || need+=(busybox-static)
command -v cpio >/dev/null || need+=(cpio)
command -v candump >/dev/null || need+=(can-utils)
if [ ${#need[@]} -gt 0 ]; then
    echo "vcan: installing ${need[*]}"
    apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "${need[@]}" >/dev/null
fi

kpkg=$(apt-cache depends linux-image-amd64 2>/dev/null | awk '/Depends: linux-image-[0-9]/ {print $2; exit}')
if [ -z "$kpkg" ]; then apt-get update -qq; kpkg=$(apt-cache depends linux-image-amd64 | awk '/Depends: linux-image-[0-9]/ {print $2; exit}'); fi
deb=$(ls "$cache"/"$kpkg"_*.deb 2>/dev/null | head -1 || true)
if [ -z "$deb" ]; then
    (cd "$cache" && apt-get download "$kpkg" 2>/dev/null)
    deb=$(ls "$cache"/"$kpkg"_*.deb | head -1)
fi
if [ "${1:-}" = "--prepare" ]; then
    echo "vcan: prepared ($kpkg, qemu, busybox, cpio, candump)"
    exit 0
fi
# (not in --prepare: CI's own pip install runs beside it)
python3 -c "import cantools" 2>/dev/null || python3 -m pip install --quiet --disable-pip-version-check cantools
dpkg -x "$deb" "$work/k"
kver=${kpkg#linux-image-}
mods="$work/k/lib/modules/$kver/kernel"

target=${CARGO_TARGET_DIR:-$root/target}
# the dev profile (dependencies optimised, ours at opt-level 1): what `cargo test` built already
echo "vcan: building the binaries"
# with an example: the build then has the dev-dependencies' features (tokio's test-util, the
# feature pins in Cargo.toml), the set `cargo test` built, so CI reuses that build instead of
# compiling tokio, its dependants and the library a second time (the binaries behave the same)
(cd "$root" && cargo build --quiet --bin pa10 --bin pa10d --example stress)

ird="$work/initrd"
mkdir -p "$ird"/{bin,sbin,proc,sys,dev,tmp,etc,modules}
cp /bin/busybox "$ird/bin/"
for m in net/can/can.ko net/can/can-raw.ko drivers/net/can/dev/can-dev.ko drivers/net/can/vcan.ko; do
    cp "$mods/$m" "$ird/modules/"
done
ipbin=$(command -v ip)
cp "$ipbin" "$ird/sbin/ip"
cp "$target/debug/pa10" "$target/debug/pa10d" "$(command -v candump)" "$ird/bin/"
# without their debug information (hundreds of MB in an initrd the emulated CPU unpacks)
strip "$ird/bin/pa10" "$ird/bin/pa10d"
for f in "$ird/sbin/ip" "$ird/bin/pa10" "$ird/bin/pa10d" "$ird/bin/candump"; do
    for lib in $(ldd "$f" | grep -o '/[^ ]*'); do
        mkdir -p "$ird$(dirname "$lib")"
        cp -L "$lib" "$ird$lib"
    done
done
cp "$root/config/model-nominal.yaml" "$ird/etc/"
# the daemon on vcan0; an emulated CPU is slow, so 100 Hz and wide safety margins
sed -e 's/backend: virtual/backend: socketcan\n  interface: vcan0/' \
    -e 's/rate_hz: 500 .*/rate_hz: 100/' \
    -e 's/feedback_timeout_ms: 20/feedback_timeout_ms: 300/' \
    -e 's/controller_watchdog_ms: 50/controller_watchdog_ms: 255/' \
    -e 's/following_error: 0.01/following_error: 0.05/' \
    -e 's|socket: /tmp/pa10d-sim.sock|socket: /tmp/pa10d.sock|' \
    -e '/^sim:/,$d' "$root/config/sim.yaml" | sed 's/\\n/\n/' > "$ird/etc/vcan.yaml"
# the FD variant: the same daemon on vcan1 with one COMMAND_FD / FEEDBACK_FD a cycle
sed -e 's/interface: vcan0/interface: vcan1\n  fd: true\n  data_bitrate: 5000000/' \
    -e 's|socket: /tmp/pa10d.sock|socket: /tmp/pa10d-fd.sock|' "$ird/etc/vcan.yaml" | sed 's/\\n/\n/g' > "$ird/etc/vcan-fd.yaml"
# and the FD configuration pointed at the classic vcan0 (MTU 16): refused
sed -e 's/interface: vcan1/interface: vcan0/' "$ird/etc/vcan-fd.yaml" > "$ird/etc/vcan-fd-on-classic.yaml"
cat > "$ird/init" <<'INIT'
#!/bin/busybox sh
/bin/busybox --install -s /bin
mount -t proc proc /proc; mount -t sysfs sys /sys; mount -t devtmpfs dev /dev
for m in can can-raw can-dev vcan; do insmod /modules/$m.ko || echo "FAIL insmod $m"; done
ip link add dev vcan0 type vcan && ip link set up vcan0 && echo VCAN-UP
export PA10D_SOCKET=/tmp/pa10d.sock
candump -L vcan0 > /tmp/cap.log &
CAP=$!
pa10 sim --can vcan0 --seed 3 &
SIM=$!
pa10d --config /etc/vcan.yaml 2>/tmp/pa10d.log &
i=0; while [ ! -S /tmp/pa10d.sock ] && [ $i -lt 100 ]; do sleep 0.1; i=$((i+1)); done
k=1
for q in "0.1 0.45 1.55 0 1.1 -0.1" "-0.2 0.6 1.3 0.2 0.9 0.3" "0.3 0.35 1.7 -0.1 1.2 0.0"; do
    if pa10 move joints --wait $q >/dev/null; then echo "MOVE$k-OK $q"; else echo "MOVE$k-FAIL $q"; fi
    echo "STATUS$k $(pa10 status --json)"
    k=$((k+1))
done
kill $CAP
echo CAPTURE-BEGIN
head -n 400 /tmp/cap.log
echo CAPTURE-END
kill $SIM
sleep 1
echo "STATUS-AFTER-KILL $(pa10 status --json)"
echo DAEMON-LOG-BEGIN; tail -n 20 /tmp/pa10d.log; echo DAEMON-LOG-END
# CAN FD on vcan1 (MTU 72)
ip link add dev vcan1 type vcan && ip link set vcan1 mtu 72 && ip link set up vcan1 && echo VCAN-FD-UP
export PA10D_SOCKET=/tmp/pa10d-fd.sock
# vcan's default MTU is CAN FD's (72): make vcan0 a classic-only interface (16) first
ip link set vcan0 down && ip link set vcan0 mtu 16 && ip link set up vcan0 && echo "VCAN0-MTU $(cat /sys/class/net/vcan0/mtu) VCAN1-MTU $(cat /sys/class/net/vcan1/mtu)"
if pa10d --config /etc/vcan-fd-on-classic.yaml 2>/tmp/refused.log; then echo "FD-ON-CLASSIC-STARTED"; else echo "FD-ON-CLASSIC-REFUSED $(tail -n 3 /tmp/refused.log | tr '\n' ' ')"; fi
candump -L vcan1 > /tmp/capfd.log &
CAP=$!
pa10 sim --can vcan1 --fd --seed 3 &
SIM=$!
pa10d --config /etc/vcan-fd.yaml 2>/tmp/pa10d-fd.log &
i=0; while [ ! -S /tmp/pa10d-fd.sock ] && [ $i -lt 100 ]; do sleep 0.1; i=$((i+1)); done
k=1
for q in "0.1 0.45 1.55 0 1.1 -0.1" "-0.2 0.6 1.3 0.2 0.9 0.3"; do
    if pa10 move joints --wait $q >/dev/null; then echo "FDMOVE$k-OK $q"; else echo "FDMOVE$k-FAIL $q"; fi
    echo "FDSTATUS$k $(pa10 status --json)"
    k=$((k+1))
done
kill $CAP
echo CAPFD-BEGIN
head -n 300 /tmp/capfd.log
echo CAPFD-END
echo FD-DAEMON-LOG-BEGIN; tail -n 20 /tmp/pa10d-fd.log; echo FD-DAEMON-LOG-END
kill $SIM
poweroff -f
INIT
chmod +x "$ird/init"
(cd "$ird" && find . | cpio -o -H newc 2>/dev/null | gzip -1 > "$work/initrd.gz")

echo "vcan: booting $kpkg under QEMU (TCG)"
timeout 600 qemu-system-x86_64 -accel tcg -m 1024 -smp 2 -nographic -no-reboot \
    -kernel "$work/k/boot/vmlinuz-$kver" -initrd "$work/initrd.gz" \
    -append "console=ttyS0 panic=-1 edd=off quiet" > "$work/console.log" 2>&1 || true
tr -d '\r' < "$work/console.log" > "$work/console.txt"

fail() {
    echo "vcan: FAILED: $*" >&2
    echo "---- VM console ----" >&2
    cat "$work/console.txt" >&2
    exit 1
}
grep -q VCAN-UP "$work/console.txt" || fail "vcan0 did not come up"
sed -n '/^CAPTURE-BEGIN$/,/^CAPTURE-END$/p' "$work/console.txt" | grep '^(' > "$work/cap.log" || true
[ -s "$work/cap.log" ] || fail "no traffic captured"
"$target/debug/pa10" sim decode "$work/cap.log" > "$work/expected.json" || fail "the codec cannot decode the capture"
python3 "$root/tests/dbc/check_dbc.py" "$root/docs/pa10.dbc" "$work/cap.log" "$work/expected.json" || fail "cantools and the codec disagree on the capture"
# the moves a scenario printed (PREFIXn-OK q… then PREFIX-status lines) landed where they were sent
cat > "$work/moves.py" <<'PY'
import json, sys
console, move, status, count, framing = sys.argv[1:6]
lines = open(console).read().splitlines()
targets = {}
for l in lines:
    if l.startswith(move) and ("-OK " in l or "-FAIL " in l):
        k, rest = l.split(" ", 1)
        assert k.endswith("-OK"), f"move failed: {l}"
        targets[k[len(move):-3]] = [float(x) for x in rest.split()]
assert len(targets) == int(count), f"expected {count} moves, saw {targets}"
for k, q in targets.items():
    st = next(json.loads(l.split(" ", 1)[1]) for l in lines if l.startswith(f"{status}{k} "))["status"]
    assert st["state"] == "holding", st
    assert st["cycle"]["framing"] == framing, st["cycle"]
    if framing == "fd":
        assert st["link"]["incomplete"] == 0 or st["link"]["cycles"] > 50 * st["link"]["incomplete"], st["link"]
    for j in range(6):
        assert abs(st["setpoint"][j] - q[j]) < 1e-9, (k, j, st["setpoint"], q)
        # the resolver sits where the (rigid nominal) model puts the motor: at the setpoint
        assert abs(st["q_motor"][j] - q[j]) < 2e-3, (k, j, st["q_motor"], q)
print(f"vcan: {count} {framing} moves landed")
PY
python3 "$work/moves.py" "$work/console.txt" MOVE STATUS 3 classic || fail "scenario checks"
python3 - "$work/console.txt" <<'PY' || fail "scenario checks"
import json, sys
lines = open(sys.argv[1]).read().splitlines()
after = next(json.loads(l.split(" ", 1)[1]) for l in lines if l.startswith("STATUS-AFTER-KILL "))["status"]
assert after["state"] == "fault" and "stale feedback" in (after["fault"] or ""), after
print(f"vcan: capture of {len(lines)} console lines checked, feedback-timeout stop seen: {after['fault']}")
PY
grep -q VCAN-FD-UP "$work/console.txt" || fail "vcan1 (MTU 72) did not come up"
grep "FD-ON-CLASSIC-REFUSED" "$work/console.txt" | grep -q "MTU 16, not a CAN FD interface" || fail "pa10d did not refuse CAN FD on vcan0 (MTU 16) with the MTU named"
sed -n '/^CAPFD-BEGIN$/,/^CAPFD-END$/p' "$work/console.txt" | grep '^(' > "$work/capfd.log" || true
grep -q '##' "$work/capfd.log" || fail "no CAN FD frames captured on vcan1"
"$target/debug/pa10" sim decode "$work/capfd.log" > "$work/expected-fd.json" || fail "the codec cannot decode the FD capture"
python3 "$root/tests/dbc/check_dbc.py" "$root/docs/pa10-fd.dbc" "$work/capfd.log" "$work/expected-fd.json" || fail "cantools and the codec disagree on the FD capture"
python3 "$work/moves.py" "$work/console.txt" FDMOVE FDSTATUS 2 fd || fail "FD scenario checks"
echo "vcan: CAN FD: $(grep -c '##' "$work/capfd.log") FD frames in the capture"
# ten checks: vcan up, capture decoded, DBC agrees, three moves landed, feedback-timeout stop;
# vcan1 (MTU 72) up, FD refused on MTU 16, FD capture decoded, FD DBC agrees, two FD moves landed
echo "vcan: 10 passed, 0 failed"
