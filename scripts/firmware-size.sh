#!/usr/bin/env bash
# Builds the B-G431B-ESC1 firmware and prints its flash and static RAM use against the
# budget (64 KiB flash, 16 KiB static RAM); exits non-zero when over budget. The STM32G431CB
# has 124 KiB of program flash beside the two coefficient pages (memory.x): the budget keeps
# half of it free (a bootloader, a second image).
#
#   flash = text + data   (code, read-only data, vector table, initial values of .data)
#   RAM   = data + bss    (static RAM: .data, .bss, .uninit; the stack takes the rest)
#
# Sizes come from `arm-none-eabi-size` (Debian package binutils-arm-none-eabi, installed
# here when missing); `llvm-size` is used when that cannot be installed.
set -euo pipefail
cd "$(dirname "$0")/.."

FLASH_BUDGET=$((64 * 1024))
RAM_BUDGET=$((16 * 1024))
TARGET=thumbv7em-none-eabihf

if command -v rustup >/dev/null 2>&1 && ! rustup target list --installed | grep -qx "$TARGET"; then
  rustup target add "$TARGET"
fi

cargo build --release -p firmware --target "$TARGET"
elf="${CARGO_TARGET_DIR:-target}/$TARGET/release/firmware"
[ -f "$elf" ] || { echo "error: $elf: firmware ELF not found after the build" >&2; exit 1; }

if ! command -v arm-none-eabi-size >/dev/null 2>&1 && command -v apt-get >/dev/null 2>&1; then
  sudo=""
  [ "$(id -u)" -eq 0 ] || sudo="sudo"
  echo "installing binutils-arm-none-eabi (for arm-none-eabi-size)..." >&2
  { $sudo apt-get update -qq && $sudo apt-get install -y -qq binutils-arm-none-eabi; } >&2 || true
fi
if command -v arm-none-eabi-size >/dev/null 2>&1; then
  size_tool=arm-none-eabi-size
elif command -v llvm-size >/dev/null 2>&1; then
  size_tool=llvm-size
else
  echo "error: neither arm-none-eabi-size nor llvm-size is available to measure $elf" >&2
  exit 1
fi

# Berkeley format: text data bss dec hex filename.
read -r text data bss _ < <("$size_tool" -B "$elf" | awk 'NR == 2 { print $1, $2, $3, $4 }')
flash=$((text + data))
ram=$((data + bss))
pct() { awk -v a="$1" -v b="$2" 'BEGIN { printf "%.1f", 100 * a / b }'; }

echo "firmware: $elf (sizes by $size_tool)"
printf '  text %7d   data %7d   bss %7d\n' "$text" "$data" "$bss"
printf '  flash %6d B of %6d B budget (%s %%)\n' "$flash" "$FLASH_BUDGET" "$(pct "$flash" "$FLASH_BUDGET")"
printf '  RAM   %6d B of %6d B budget (%s %%) static\n' "$ram" "$RAM_BUDGET" "$(pct "$ram" "$RAM_BUDGET")"

status=0
if [ "$flash" -gt "$FLASH_BUDGET" ]; then
  echo "error: flash use $flash B exceeds the budget of $FLASH_BUDGET B" >&2
  status=1
fi
if [ "$ram" -gt "$RAM_BUDGET" ]; then
  echo "error: static RAM use $ram B exceeds the budget of $RAM_BUDGET B" >&2
  status=1
fi
exit $status
