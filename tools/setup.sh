#!/usr/bin/env bash
# SPDX-License-Identifier: MIT
# Installs voxlight's build and test dependencies from Debian packages. Idempotent; quiet when all are present.
set -euo pipefail

packages=(
  build-essential cmake ninja-build pkg-config git
  libvtk9-dev libgdcm-dev libgdcm-tools libvtkgdcm-dev
  libcgal-dev libopenmesh-dev libglfw3-dev libx11-dev libglm-dev libopenimageio-dev openimageio-tools
  libtbb-dev libeigen3-dev zlib1g-dev nlohmann-json3-dev libcli11-dev libimgui-dev libstb-dev
  libtinygltf-dev libopenmpi-dev openmpi-bin
  libgtest-dev libgmock-dev libbenchmark-dev clang-format
  clang-14 libclang-rt-14-dev
  xvfb xauth mesa-utils libgl1-mesa-dri libgl-dev libegl-dev
  python3-numpy python3-matplotlib python3-vtk9 python3-nibabel mricron-data
)

missing=()
for p in "${packages[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then
    missing+=("$p")
  fi
done

if [ ${#missing[@]} -eq 0 ]; then
  exit 0
fi

echo "voxlight setup: installing ${#missing[@]} Debian packages: ${missing[*]}"
SUDO=""
if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -qq
$SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
echo "voxlight setup: done"
