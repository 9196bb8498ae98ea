#!/usr/bin/env bash
# Installs the Debian packages that the real-peer tests use, when we are root and
# they are missing. Elsewhere it says what is missing; those tests then skip with
# the reason (or fail, under CI=true / VSTIG_REQUIRE_*).
set -u
want=()
command -v gcc >/dev/null || want+=(gcc)
command -v make >/dev/null || want+=(make)  # libvstig's Makefile (firmware_spec/libvstig)
# Python's headers, for the compiled data path (vstig_hw._vstig) that `make test` builds
python3 -c 'import os, sysconfig; raise SystemExit(not os.path.exists(sysconfig.get_paths()["include"] + "/Python.h"))' \
  2>/dev/null || want+=(python3-dev)
command -v avr-gcc >/dev/null || want+=(gcc-avr binutils-avr)  # libvstig for the Kilobot's ATmega328P
[ -e /usr/lib/avr/include/avr/io.h ] || want+=(avr-libc)
[ -e /usr/include/simavr/sim_avr.h ] || want+=(libsimavr-dev)  # the simulated AVR robot's board (tests/cli)
command -v g++ >/dev/null || want+=(g++)  # with gcc and Python's headers: the vstig_msgs ROS 2 interfaces
python3 -c 'import sysconfig, os, sys; sys.exit(not os.path.exists(sysconfig.get_paths()["include"] + "/Python.h"))' \
  || want+=(python3-dev)
command -v linux.uml >/dev/null || [ -x /usr/bin/linux.uml ] || want+=(user-mode-linux)
command -v modprobe >/dev/null || [ -x /sbin/modprobe ] || want+=(kmod)
command -v cansend >/dev/null || want+=(can-utils)
command -v tshark >/dev/null || want+=(tshark)
command -v text2pcap >/dev/null || want+=(wireshark-common)  # pcaps of XBee frames for the dissector (tests/spec, docs/how-to/xbee.md)
command -v ip >/dev/null || want+=(iproute2)  # network namespaces for the zenoh federation tests
command -v node >/dev/null || want+=(nodejs)  # Foxglove's WebSocket client, the live view's viewer in tests
command -v npm >/dev/null || want+=(npm)
command -v chromium >/dev/null || want+=(chromium)  # the docs site looked at in a real browser (tests/docs)
command -v prometheus >/dev/null || want+=(prometheus)  # a real Prometheus scrapes --metrics (tests/cli/test_metrics.py)
command -v systemd-analyze >/dev/null || want+=(systemd)  # `systemd-analyze verify` checks `vstig service`'s unit
[ ${#want[@]} -eq 0 ] && exit 0
if [ "$(id -u)" -ne 0 ]; then
  echo "sysdeps: not root, cannot install: ${want[*]} (their tests will skip)" >&2
  exit 0
fi
echo "sysdeps: installing ${want[*]}" >&2
export DEBIAN_FRONTEND=noninteractive
echo "wireshark-common wireshark-common/install-setuid boolean false" | debconf-set-selections 2>/dev/null || true
apt-get -o DPkg::Lock::Timeout=300 update -qq >/dev/null 2>&1 || true
apt-get -o DPkg::Lock::Timeout=300 install -y -qq --no-install-recommends "${want[@]}" >/dev/null 2>&1 \
  || echo "sysdeps: apt-get could not install ${want[*]} (their tests will skip)" >&2
exit 0
