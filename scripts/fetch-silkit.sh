#!/usr/bin/env bash
# Puts Vector SIL Kit's libSilKit.so and its sil-kit-registry and sil-kit-system-controller
# programs into target/silkit/silkit-py-1.0.5/, taken from the silkit-py 1.0.5 wheel on PyPI
# (SIL Kit 5.0.3, MIT licence). Does nothing when they are already there.
#
# Exit status: 0 when the files are in place, 2 when the wheel cannot be fetched because this
# machine has no network (the SIL Kit tests then say so and skip), 1 on any other failure.
# Prints the directory on success.
set -euo pipefail

cd "$(dirname "$0")/.."
version=1.0.5
dir="target/silkit/silkit-py-$version"
files=(libSilKit.so sil-kit-registry sil-kit-system-controller)

complete() {
    local f
    for f in "${files[@]}"; do
        [ -s "$dir/$f" ] || return 1
    done
}

if complete; then
    echo "$dir"
    exit 0
fi

python=""
for p in python3 python; do
    if command -v "$p" >/dev/null 2>&1 && "$p" -m pip --version >/dev/null 2>&1; then
        python="$p"
        break
    fi
done
if [ -z "$python" ]; then
    echo "fetch-silkit: pip is needed to fetch the silkit-py wheel (python3 -m pip)" >&2
    exit 1
fi

mkdir -p target/silkit
work="$(mktemp -d target/silkit/fetch.XXXXXX)"
trap 'rm -rf "$work"' EXIT

# The wheel is built for CPython 3.12; pip fetches it for any local Python with
# --python-version, since nothing is installed.
if ! "$python" -m pip download --quiet --no-deps --only-binary=:all: --python-version 3.12 \
    "silkit-py==$version" -d "$work" >"$work/pip.log" 2>&1; then
    if ! "$python" - <<'PY' >/dev/null 2>&1; then
import socket
socket.create_connection(("pypi.org", 443), timeout=10).close()
PY
        echo "fetch-silkit: no network (pypi.org unreachable): SIL Kit cannot be fetched" >&2
        exit 2
    fi
    cat "$work/pip.log" >&2
    echo "fetch-silkit: pip could not download silkit-py==$version" >&2
    exit 1
fi

wheel="$(ls "$work"/silkit_py-"$version"-*.whl)"
mkdir -p "$work/unpacked"
# A wheel is a zip archive; Python's zipfile module unpacks it where unzip is not installed.
"$python" - "$wheel" "$work/unpacked" <<'PY'
import sys, zipfile
with zipfile.ZipFile(sys.argv[1]) as z:
    for name in z.namelist():
        if name.startswith("SilKit_py/bin/") or name.startswith("SilKit_py/licenses/"):
            z.extract(name, sys.argv[2])
PY
staged="$work/staged"
mkdir -p "$staged"
for f in "${files[@]}" sil-kit-monitor; do
    if [ -f "$work/unpacked/SilKit_py/bin/$f" ]; then
        cp "$work/unpacked/SilKit_py/bin/$f" "$staged/$f"
    fi
done
cp -r "$work/unpacked/SilKit_py/licenses" "$staged/licenses"
chmod +x "$staged"/sil-kit-*
# The programs find libSilKit.so beside them ($ORIGIN in their run path).
rm -rf "$dir"
mv "$staged" "$dir"
if ! complete; then
    echo "fetch-silkit: the wheel did not hold ${files[*]}" >&2
    exit 1
fi
echo "$dir"
