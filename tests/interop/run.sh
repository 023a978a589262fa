#!/usr/bin/env bash
# Interop suite: python-can, python-canopen and tshark against `cantwin sim`.
#
# Creates (or reuses) a virtualenv inside the cargo target directory, installs the pinned
# clients, builds the `cantwin` binary and runs pytest on this folder. Exits non-zero when
# any test fails or when no test ran at all.
set -euo pipefail

here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
root="$(cd "$here/../.." && pwd)"
target="${CARGO_TARGET_DIR:-$root/target}"
case "$target" in
  /*) ;;
  *) target="$root/$target" ;;
esac
venv="$target/interop-venv"
python="${PYTHON:-python3}"

if [ ! -x "$venv/bin/python" ]; then
  "$python" -m venv "$venv"
fi
# Reinstall only when the requirements changed since the last successful install.
stamp="$venv/.requirements.stamp"
if ! cmp -s "$here/requirements.txt" "$stamp" 2>/dev/null; then
  "$venv/bin/python" -m pip install --quiet --disable-pip-version-check -r "$here/requirements.txt"
  cp "$here/requirements.txt" "$stamp"
fi

(cd "$root" && cargo build --quiet --bin cantwin)
export CANTWIN_BIN="$target/debug/cantwin"
export CANTWIN_SCENARIOS="$root/scenarios"

status=0
(cd "$here" && "$venv/bin/python" -m pytest -q -p no:cacheprovider "$@" "$here") || status=$?
if [ "$status" -eq 5 ]; then
  echo "interop: pytest collected no tests" >&2
  exit 1
fi
exit "$status"
