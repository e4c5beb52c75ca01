#!/usr/bin/env bash
# Installs what the viewer's browser tests need, never failing the build when it cannot:
#   - the Playwright Python package into the venv (it drives an existing Chromium; no browser
#     download: the tests launch /usr/bin/chromium);
#   - Debian's chromium package, when /usr/bin/chromium is missing and apt-get can run (as
#     root, or through passwordless sudo).
# Without them, tests/test_viewer.py skips its browser tests and says which part is missing.
# Usage: scripts/install_browser.sh VENV_PYTHON
set -u
py="${1:-.venv/bin/python}"

if ! "$py" -c 'import playwright' 2>/dev/null; then
    "$py" -m pip install --quiet playwright \
        || echo "install_browser: note: could not pip install playwright; browser tests will be skipped" >&2
fi

chromium="${TOPOMECH_CHROMIUM:-/usr/bin/chromium}"
if [ -x "$chromium" ]; then
    exit 0
fi
if [ "$(id -u)" -eq 0 ]; then
    as_root=()
elif command -v sudo >/dev/null 2>&1 && sudo -n true 2>/dev/null; then
    as_root=(sudo -n)
else
    echo "install_browser: note: no $chromium and no root to install Debian's chromium; browser tests will be skipped" >&2
    exit 0
fi
if ! command -v apt-get >/dev/null 2>&1; then
    echo "install_browser: note: no $chromium and no apt-get; browser tests will be skipped" >&2
    exit 0
fi
echo "install_browser: installing Debian's chromium (apt-get)" >&2
export DEBIAN_FRONTEND=noninteractive
if ! "${as_root[@]}" apt-get install -y -q chromium >/dev/null 2>&1; then
    "${as_root[@]}" apt-get update -q >/dev/null 2>&1
    "${as_root[@]}" apt-get install -y -q chromium >/dev/null 2>&1 \
        || echo "install_browser: note: apt-get install chromium failed; browser tests will be skipped" >&2
fi
exit 0
