#!/usr/bin/env bash
# The whole cantwin test suite: formatting, lints, every Rust test, and the interop suite
# against third-party tools. Installs what it needs by itself (tshark, chromium and
# chromium-driver from Debian's packages, a Python virtualenv with pinned python-can/canopen
# for the interop suite) and exits non-zero on any failure.
set -euo pipefail

cd "$(dirname "$0")/.."
export CARGO_TERM_COLOR="${CARGO_TERM_COLOR:-never}"
# Property tests: bounded case counts keep the suite short on small machines. Tests that set
# their own count keep it.
export PROPTEST_CASES="${PROPTEST_CASES:-64}"

step() { printf '\n==> %s\n' "$*"; }

# Installs Debian packages (no recommended packages) unless COMMAND is already there; when
# that cannot be done here (not root, no sudo, no apt-get) the tests that need it say so.
install_debian() {
    local command="$1"
    shift
    if command -v "$command" >/dev/null 2>&1; then
        return 0
    fi
    local sudo=""
    if [ "$(id -u)" -ne 0 ]; then
        if command -v sudo >/dev/null 2>&1 && sudo -n true 2>/dev/null; then
            sudo="sudo -n"
        else
            echo "$command is not installed and packages cannot be installed here (not root, no sudo): tests that need it will say so"
            return 0
        fi
    fi
    if ! command -v apt-get >/dev/null 2>&1; then
        echo "$command is not installed and there is no apt-get here: tests that need it will say so"
        return 0
    fi
    step "installing $* (Debian packages, no recommended packages)"
    if [ -z "${apt_updated:-}" ]; then
        DEBIAN_FRONTEND=noninteractive $sudo apt-get update -qq || true
        apt_updated=1
    fi
    DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq --no-install-recommends "$@" \
        || echo "$* could not be installed: tests that need $command will say so"
}

# tshark for the interop suite; its setuid question is answered first so the install does
# not stop to ask.
if ! command -v tshark >/dev/null 2>&1; then
    echo "wireshark-common wireshark-common/install-setuid boolean false" \
        | { [ "$(id -u)" -eq 0 ] && debconf-set-selections || sudo -n debconf-set-selections; } 2>/dev/null || true
fi
install_debian tshark tshark
# Headless Chromium and its WebDriver for the web dashboard's browser test
# (crates/cli/tests/web.rs), driven from their system paths.
install_debian chromedriver chromium chromium-driver

step "cargo fmt --check"
cargo fmt --all -- --check

step "cargo clippy (all targets, all features, warnings are errors)"
cargo clippy --workspace --all-targets --all-features -- -D warnings

# Vector SIL Kit 5.0.3 (libSilKit.so, sil-kit-registry, sil-kit-system-controller) from the
# silkit-py wheel on PyPI, for crates/silkit's tests; without network (status 2) those tests
# say so and skip.
step "fetching SIL Kit for the SIL Kit tests"
silkit_status=0
scripts/fetch-silkit.sh || silkit_status=$?
[ "$silkit_status" -eq 0 ] || [ "$silkit_status" -eq 2 ]

step "cargo test"
cargo test --workspace

# The Python package's crate links against Python and is not a workspace member: its own
# formatting and lint checks (its tests are Python, run by the interop suite).
step "python package: cargo fmt --check and clippy"
(cd python && cargo fmt -- --check && cargo clippy --all-targets --all-features -- -D warnings)

if [ -x tests/interop/run.sh ]; then
    step "interop suite (python-can, python-canopen, tshark)"
    tests/interop/run.sh
fi

step "all checks passed"
