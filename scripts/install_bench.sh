#!/usr/bin/env bash
# System libraries for offscreen VTK rendering (the comparison suite, benchmarks/compare.py).
#
# The PyPI vtk wheels (>= 9.4) pick their OpenGL window at run time: X11 when a display exists,
# otherwise EGL (vtkEGLRenderWindow) or OSMesa (vtkOSOpenGLRenderWindow). Neither needs a GPU: with
# Mesa both run on the llvmpipe software rasterizer. Those classes dlopen the system's libEGL /
# libOSMesa, which the wheel does not ship, so a machine without a display or GPU needs:
#
#   libosmesa6       libOSMesa.so.8    (vtkOSOpenGLRenderWindow, Mesa's offscreen software GL)
#   libegl1          libEGL.so.1       (glvnd EGL loader, vtkEGLRenderWindow)
#   libegl-mesa0     Mesa's EGL vendor library (surfaceless platform)
#   libgl1-mesa-dri  the swrast/llvmpipe driver EGL loads
#   libgbm1          buffer manager Mesa's EGL links against
#   libxrender1 libxt6 libx11-6  X libraries the wheel's modules link against even offscreen
#
# Usage: scripts/install_bench.sh [--optional]
#   --optional  never fail: report what could not be installed and exit 0. (`make test` runs the
#               strict form and treats a failure as optional itself, so it can retry next time.)
# Debian/Ubuntu (apt-get) only; on other systems install the same libraries by hand.
set -uo pipefail

optional=0
[[ "${1:-}" == "--optional" ]] && optional=1

packages=(libosmesa6 libegl1 libegl-mesa0 libgl1-mesa-dri libgbm1 libxrender1 libxt6 libx11-6)

script=install_bench.sh
skip_note="VTK comparison tests will skip"
elsewhere="install OSMesa or EGL (Mesa) libraries by hand"
already="system libraries for offscreen VTK already installed"
# shellcheck source=apt_install.sh
source "$(dirname "${BASH_SOURCE[0]}")/apt_install.sh"
apt_install
