#!/bin/sh
# Install the system libraries Qt (PySide6) needs, and HDF5's command-line tools (h5dump,
# h5clear: the independent check that our logs are plain HDF5) and libusb (pyvisa-py's USB
# backend, for the function generator), when missing and root.  gcc and libc6-dev compile
# the exported firmware kit in its tests; tshark runs the exported Wireshark dissector
# (its debconf question, non-root capture, takes the default "no" non-interactively).
# Debian/Ubuntu package names; other systems: install the equivalents by hand.
set -eu
PKGS="libegl1 libgl1 libglib2.0-0 libfontconfig1 libxkbcommon0 libxkbcommon-x11-0 libdbus-1-3 \
libxcb-cursor0 libxcb-icccm4 libxcb-keysyms1 libxcb-shape0 libxcb-xinerama0 libxcb-randr0 \
libxcb-render-util0 libxcb-image0 libxrender1 libxi6 libsm6 libice6 hdf5-tools libusb-1.0-0 \
gcc libc6-dev tshark"
missing=""
if ! command -v dpkg-query >/dev/null 2>&1; then
  echo "system-deps: not a Debian-like system; make sure Qt 6's runtime libraries (EGL, GL, fontconfig, xkbcommon, xcb-cursor) are installed" >&2
  exit 0
fi
for p in $PKGS; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing="$missing $p"
done
[ -z "$missing" ] && exit 0
if [ "$(id -u)" != "0" ]; then
  echo "system-deps: missing system packages:$missing" >&2
  echo "system-deps: run 'sudo apt-get install$missing' (continuing; Qt may fail to start)" >&2
  exit 0
fi
echo "system-deps: installing$missing"
export DEBIAN_FRONTEND=noninteractive
apt-get update -qq >/dev/null || echo "system-deps: apt-get update failed, trying the install anyway" >&2
apt-get install -y -qq --no-install-recommends $missing >/dev/null
