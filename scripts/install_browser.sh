#!/usr/bin/env bash
# Install the headless browser of the browser tests (tests/test_viz.py, marker `browser`):
# Debian's chromium, driven by Playwright's Python API through executable_path=/usr/bin/chromium.
# No browser is downloaded by Playwright (never run `playwright install`).
#
# Idempotent: does nothing when /usr/bin/chromium exists. Where apt is unavailable (not Debian or
# Ubuntu, or no root), it says so and exits 0: the browser tests then skip with that reason.
set -euo pipefail

CHROMIUM=/usr/bin/chromium

if [ -x "$CHROMIUM" ]; then
    echo "install_browser: $CHROMIUM is already installed ($("$CHROMIUM" --version 2>/dev/null || echo 'version unknown'))"
    exit 0
fi

if ! command -v apt-get >/dev/null 2>&1; then
    echo "install_browser: apt-get is not available; install chromium at $CHROMIUM by hand. The browser tests will be skipped."
    exit 0
fi

SUDO=""
if [ "$(id -u)" -ne 0 ]; then
    if command -v sudo >/dev/null 2>&1 && sudo -n true 2>/dev/null; then
        SUDO="sudo -n"
    else
        echo "install_browser: not root and no password-less sudo; cannot apt-get install chromium. The browser tests will be skipped."
        exit 0
    fi
fi

echo "install_browser: installing Debian's chromium with apt-get"
if ! $SUDO apt-get update || ! DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y chromium; then
    echo "install_browser: apt-get could not install chromium (no package or no network). The browser tests will be skipped."
    exit 0
fi

if [ -x "$CHROMIUM" ]; then
    echo "install_browser: installed $("$CHROMIUM" --version 2>/dev/null || echo "$CHROMIUM")"
else
    echo "install_browser: apt-get finished but $CHROMIUM is missing. The browser tests will be skipped."
fi
