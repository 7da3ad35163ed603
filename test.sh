#!/usr/bin/env bash
# The whole test suite, set up and run: what CI runs (`.ci/run` calls this
# and nothing else), and what a newcomer runs on a fresh machine that has
# a Rust toolchain (rustup), Python 3 and a C compiler.
#
#   ./test.sh
#
# 1. Checks, before anything is built, every tool a test needs, and stops
#    naming what is missing and which tests need it. As root it installs
#    the Debian packages itself (Chromium, util-linux, iproute2, openssl,
#    python3-venv); as another user it says what to install.
# 2. Sets up what it owns, under the cargo target dir: a Python virtual
#    environment with the test clients' pinned packages
#    (tests/clients/requirements.txt; no system pip); and the nightly
#    toolchain and cargo-fuzz, which only the fuzzing step uses (installed
#    before the build all the same, so that a failure shows at once).
# 3. Runs fmt, clippy (-D warnings, every feature), the default build,
#    every test of the workspace with every feature (`client-tests`
#    included: nothing is skipped) and the fuzzers (fuzz/run, 20 s each).
# 4. Ends with the totals line: passed, failed, ignored, fuzz targets.
#
# Environment: CARGO_TARGET_DIR (default ~/.cache/squall-target, kept
# between runs), SQUALL_FUZZ_SECS (default 20; 0 skips fuzzing).
set -euo pipefail
# The whole script is one function, read before any of it runs: editing
# or checking out this file while a run goes cannot change what it does.
main() {
    cd "$(dirname "$0")"
    export CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-$HOME/.cache/squall-target}"
    export CARGO_TERM_COLOR=never
    fuzz_secs="${SQUALL_FUZZ_SECS:-20}"
    env_dir="$CARGO_TARGET_DIR/test-env"
    venv="$env_dir/python"
    requirements=tests/clients/requirements.txt
    root=false
    [ "$(id -u)" -eq 0 ] && root=true

    step() { printf '\n== %s\n' "$*" >&2; }

    # --- 1. What the tests need, before the build --------------------------

    missing=()
    packages=()
    # need TOOL WHO-NEEDS-IT DEBIAN-PACKAGE: records TOOL as missing unless it
    # is on PATH (or installed here, as root, from Debian's package).
    apt_updated=false
    apt_install() {
        if ! $apt_updated; then
            apt-get update -qq > /dev/null 2>&1 || true
            apt_updated=true
        fi
        DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "$@" > /dev/null 2>&1
    }
    need() {
        local tool=$1 who=$2 package=$3
        command -v "$tool" > /dev/null && return 0
        if $root && command -v apt-get > /dev/null && apt_install "$package" && command -v "$tool" > /dev/null; then
            echo "installed $package (for $tool)" >&2
            return 0
        fi
        missing+=("$tool (Debian package $package), for $who")
        packages+=("$package")
    }

    step "checking what the tests need"
    for tool in cargo rustc rustup; do
        command -v "$tool" > /dev/null || missing+=("$tool: a Rust toolchain by rustup (https://rustup.rs)")
    done
    command -v cc > /dev/null || need gcc "building SQLite, ring and zstd (a C compiler)" gcc
    need python3 "the tests' Python clients (tests/clients)" python3
    need unshare "tests/security.rs (a private network namespace)" util-linux
    # As root, the read-only bag test drops to an unprivileged user with it.
    $root && need setpriv "tests/cli.rs (reading a bag as a user who is not root)" util-linux
    need ip "tests/security.rs (an address inside the namespace)" iproute2
    need mkfifo "tests/security.rs (a FIFO that proves a file was never opened)" coreutils
    need openssl "tests/cluster_tls.rs, tests/security.rs, tests/live_link.rs (certificates)" openssl
    chromium=""
    for name in chromium chromium-browser google-chrome; do
        if command -v "$name" > /dev/null; then
            chromium=$(command -v "$name")
            break
        fi
    done
    if [ -z "$chromium" ]; then
        need chromium "tests/watch.rs (the live page in headless Chromium)" chromium
        chromium=$(command -v chromium || true)
    fi
    if command -v python3 > /dev/null && ! python3 -c 'import venv, ensurepip' > /dev/null 2>&1; then
        if $root && command -v apt-get > /dev/null; then
            apt_install python3-venv || true
        fi
        if ! python3 -c 'import venv, ensurepip' > /dev/null 2>&1; then
            missing+=("python3's venv module (Debian package python3-venv), for the tests' Python clients")
            packages+=(python3-venv)
        fi
    fi
    data="../shared/data"
    [ -d "$data" ] || missing+=("the shared data set at $data (beside the repository), for the tests on real logs, bags and maps")
    if [ ${#missing[@]} -gt 0 ]; then
        echo "error: the test suite cannot run on this machine; missing:" >&2
        printf '  - %s\n' "${missing[@]}" >&2
        if [ ${#packages[@]} -gt 0 ]; then
            declare -A listed=()
            install=""
            for package in "${packages[@]}"; do
                [ -n "${listed[$package]:-}" ] || { listed[$package]=1; install+=" $package"; }
            done
            echo "on Debian or Ubuntu: sudo apt-get install$install" >&2
            $root || echo "(or run ./test.sh as root: it installs Debian's packages itself)" >&2
        fi
        exit 2
    fi

    # --- 2. What this script owns, under the target dir --------------------

    step "Python clients: $venv"
    mkdir -p "$env_dir"
    stamp="$venv/.requirements"
    if ! cmp -s "$requirements" "$stamp" 2> /dev/null; then
        rm -rf "$venv"
        python3 -m venv "$venv"
        "$venv/bin/python" -m pip install --quiet --disable-pip-version-check --no-input -r "$requirements"
        cp "$requirements" "$stamp"
    fi
    # The clients' modules and tools, checked: a missing one is named here,
    # not after the build.
    "$venv/bin/python" -c 'import zenoh, zenoh.ext, xxhash, rosbags, numpy, websockets, mcap' \
        || { echo "error: the Python clients' packages did not install into $venv" >&2; exit 2; }
    "$venv/bin/rosbags-convert" --help > /dev/null \
        || { echo "error: rosbags-convert did not install into $venv" >&2; exit 2; }
    # Tests run python3 and rosbags-convert from here, and this Chromium.
    export PATH="$venv/bin:$PATH"
    export SQUALL_CHROMIUM="$chromium"

    for component in rustfmt clippy; do
        rustup component list --installed 2> /dev/null | grep -q "^$component" || rustup component add "$component"
    done
    if [ "$fuzz_secs" != 0 ]; then
        step "the fuzzing step's toolchain: nightly and cargo-fuzz"
        rustup run nightly rustc --version > /dev/null 2>&1 || rustup toolchain install nightly --profile minimal
        command -v cargo-fuzz > /dev/null || cargo install --locked cargo-fuzz
    fi

    # --- 3. The suite --------------------------------------------------------

    step "fmt"
    cargo fmt --all --check
    step "clippy"
    cargo clippy --workspace --all-targets --all-features -- -D warnings
    step "build (default features: what most users build)"
    cargo build --workspace --release
    step "tests (every feature)"
    log="$env_dir/test.log"
    tests=0
    cargo test --workspace --release --all-features --no-fail-fast 2>&1 | tee "$log" || tests=$?
    fuzz="skipped (SQUALL_FUZZ_SECS=0)"
    fuzzed=0
    if [ "$fuzz_secs" != 0 ]; then
        step "fuzzing every parser for $fuzz_secs s each"
        fuzz/run "$fuzz_secs" | tee "$env_dir/fuzz.log" || fuzzed=$?
        fuzz="$(grep -c '^fuzz .* ok ' "$env_dir/fuzz.log" || true) of $(grep -c '^fuzz ' "$env_dir/fuzz.log" || true) targets ok"
    fi

    # --- 4. Totals -----------------------------------------------------------

    awk -v fuzz="$fuzz" '
        /^test result:/ {
            for (i = 1; i < NF; i++) {
                if ($(i + 1) ~ /^passed/) p += $i
                if ($(i + 1) ~ /^failed/) f += $i
                if ($(i + 1) ~ /^ignored/) g += $i
            }
        }
        END { printf "%d passed, %d failed, %d ignored; fuzz: %s\n", p, f, g, fuzz }' "$log"
    [ "$tests" -eq 0 ] && [ "$fuzzed" -eq 0 ]
}

main "$@"
