#!/usr/bin/env bash
# Interop suite: python-can, python-canopen and tshark against `cantwin sim`, and the
# `cantwin` Python package (python/) with its in-process python-can interface.
#
# Creates (or reuses) a virtualenv inside the cargo target directory, installs the pinned
# clients, builds the `cantwin` binary, builds the Python package into the virtualenv
# (maturin, release, the shared target directory) and runs pytest on this folder, then on
# the package's tests and examples. Exits non-zero when any test fails or when no test ran.
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
# The TM3 island's EDS comes from the coupler crate's own writer (an example program): built
# here, so no test waits for a compiler inside its time limit.
(cd "$root" && cargo build --quiet -p cantwin-tm3 --example tm3_eds)
# The Python package: an editable install whose native module is built in release mode.
(cd "$root/python" && VIRTUAL_ENV="$venv" CARGO_TARGET_DIR="$target" \
  "$venv/bin/maturin" develop --release --quiet)
export CANTWIN_BIN="$target/debug/cantwin"
export CANTWIN_SCENARIOS="$root/scenarios"
export CANTWIN_TM3_EDS="$target/debug/examples/tm3_eds"

run_pytest() {
  local dir="$1"
  shift
  local status=0
  (cd "$dir" && "$venv/bin/python" -m pytest -q -p no:cacheprovider "$@") || status=$?
  if [ "$status" -eq 5 ]; then
    echo "interop: pytest collected no tests in $dir" >&2
    return 1
  fi
  return "$status"
}

# Two runs: each folder imports helpers from its own conftest module.
status=0
run_pytest "$here" "$@" "$here" || status=$?
run_pytest "$root/python" "$@" tests examples || status=$?
exit "$status"
