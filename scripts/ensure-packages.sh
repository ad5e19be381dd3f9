#!/usr/bin/env bash
# Installs the given Debian/Ubuntu packages if any is missing; says exactly what to run when it
# cannot (no apt-get, not root and no sudo).
set -euo pipefail
missing=()
for p in "$@"; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
[ ${#missing[@]} -eq 0 ] && exit 0
if ! command -v cargo >/dev/null; then
    echo "error: cargo not found: install Rust (https://rustup.rs) first" >&2
fi
if ! command -v apt-get >/dev/null; then
    echo "error: missing packages ${missing[*]} and no apt-get: install the Vulkan loader, Mesa's lavapipe and the Khronos validation layers with your package manager" >&2
    exit 1
fi
sudo=""
if [ "$(id -u)" -ne 0 ]; then
    if command -v sudo >/dev/null; then sudo="sudo"; else
        echo "error: missing packages; run as root: apt-get install -y ${missing[*]}" >&2
        exit 1
    fi
fi
echo "installing ${missing[*]}" >&2
$sudo apt-get update -qq || true
DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq "${missing[@]}"
