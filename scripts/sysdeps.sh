#!/usr/bin/env bash
# Install the shared libraries that open3d and pyrealsense2 need, and the headless browser of the
# web-viewer test (Debian's chromium and its chromedriver), only where they are missing.
set -euo pipefail
need=()
ldconfig -p | grep -q 'libusb-1.0.so.0' || need+=(libusb-1.0-0)
ldconfig -p | grep -q 'libgomp.so.1' || need+=(libgomp1)
ldconfig -p | grep -q 'libGL.so.1' || need+=(libgl1)
[ -x /usr/bin/chromium ] || need+=(chromium)
[ -x /usr/bin/chromedriver ] || need+=(chromium-driver)
((${#need[@]})) || exit 0
if ! command -v apt-get >/dev/null; then
  echo "missing system libraries ${need[*]}; install them with your package manager" >&2
  exit 1
fi
sudo_=""
[ "$(id -u)" -eq 0 ] || sudo_="sudo"
echo "installing system packages: ${need[*]}"
$sudo_ apt-get update -qq
DEBIAN_FRONTEND=noninteractive $sudo_ apt-get install -y -qq "${need[@]}" >/dev/null
