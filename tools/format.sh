#!/usr/bin/env bash
# SPDX-License-Identifier: MIT
# Formats every tracked C++ file with clang-format (.clang-format); --check only reports (CI).
set -euo pipefail
cd "$(dirname "$0")/.."
mode=(-i)
if [ "${1:-}" = "--check" ]; then mode=(--dry-run --Werror); fi
git ls-files -z '*.h' '*.cpp' | xargs -0 clang-format "${mode[@]}"
