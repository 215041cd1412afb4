#!/usr/bin/env bash
# What the firmware image for the Cortex-M7 needs (`run --link qemu`, `budget --part`):
# the Rust target thumbv7em-none-eabihf, and QEMU's Arm system emulator from Debian's
# package qemu-system-arm (as root, or through sudo).
set -euo pipefail

rustup target add thumbv7em-none-eabihf

if ! command -v qemu-system-arm >/dev/null 2>&1; then
    sudo=""
    if [ "$(id -u)" -ne 0 ]; then sudo="sudo"; fi
    $sudo apt-get update -qq
    $sudo env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends qemu-system-arm
fi
qemu-system-arm --version | sed -n 1p
machines=$(qemu-system-arm -machine help)
grep -q '^mps2-an500 ' <<<"$machines" || {
    echo "this qemu-system-arm has no mps2-an500 machine (QEMU 6.0 or later has it)" >&2
    exit 1
}
