#!/usr/bin/env bash
# Regenerate requirements/lock.txt: every version the README's commands and .ci/run install,
# for the core and every extra, resolved for CPython 3.11 on x86_64 Linux (the project's machines).
# torch is resolved against the CPU build (2.13.0+cpu in /opt/wheels when present) and written
# as plain torch==2.13.0, which that build satisfies and which never pulls the CUDA packages.
# Usage: bash requirements/update-lock.sh [extra uv options, e.g. --upgrade-package highspy]
set -euo pipefail
cd "$(dirname "$0")/.."
uv_bin="${UV:-uv}"
find_links=()
[ -d /opt/wheels ] && find_links=(--find-links /opt/wheels)
# start from the current pins, so only what must move moves (uv reads its output file as preferences)
grep -v '^#' requirements/lock.txt 2>/dev/null | sed -E 's/^torch==([0-9.]+) /torch==\1+cpu /' > requirements/lock.txt.new || true
"$uv_bin" pip compile pyproject.toml --extra test --extra rl --extra bench --extra render --extra recipes \
    --python-version 3.11 --python-platform x86_64-manylinux_2_28 "${find_links[@]}" \
    --no-header --annotation-style line --quiet "$@" -o requirements/lock.txt.new
{
    echo "# The lock: exact versions for the core and every extra (CPython 3.11, x86_64 Linux)."
    echo "# Install with pip's -c (see the README); regenerate with: bash requirements/update-lock.sh"
    sed -E 's/^torch==([0-9.]+)\+cpu/torch==\1/' requirements/lock.txt.new
} > requirements/lock.txt
rm requirements/lock.txt.new
