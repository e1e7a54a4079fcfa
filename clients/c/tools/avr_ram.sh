#!/bin/sh
# Measure the decoder's static RAM on AVR (ATmega328P), where const data is
# copied to SRAM unless placed in flash: links tools/avr_ram.c with avr-gcc and
# Arduino's flags (-Os, unused sections removed) and reports .data + .bss.
#
# usage: clients/c/tools/avr_ram.sh          (also: make -C clients/c avr-ram)
#   AVR_CC   compiler (default avr-gcc); AVR_MCU (default atmega328p)
# Exits 77 if the compiler is missing.
set -eu

here=$(cd "$(dirname "$0")" && pwd)
cdir=$(cd "$here/.." && pwd)
cc=${AVR_CC:-avr-gcc}
mcu=${AVR_MCU:-atmega328p}
size=${AVR_SIZE:-avr-size}
nm=${AVR_NM:-avr-nm}
if ! command -v "$cc" >/dev/null 2>&1; then
    echo "avr_ram: $cc not found (apt-get install gcc-avr avr-libc)" >&2
    exit 77
fi
tmp=$(mktemp -d)
# A signal ends the script (its EXIT trap removes $tmp): trapping INT/TERM with the rm alone went on with the
# loop after the directory was gone, reporting a FAIL for every remaining run.
trap 'rm -rf "$tmp"' EXIT
trap 'exit 130' INT
trap 'exit 143' TERM

# ram ELF: ".data + .bss" of a linked program, in bytes
ram() {
    "$size" -A "$1" | awk '$1 == ".data" || $1 == ".bss" { n += $2 } END { print n + 0 }'
}
# symsize ELF NAME: size of a symbol, in bytes
symsize() {
    hex=$("$nm" -S "$1" | awk -v s="$2" '$4 == s { print $2 }')
    echo $((0x$hex))
}

echo "$("$cc" --version | head -1), -mmcu=$mcu -Os: static RAM (.data + .bss)"
for joints in 64 25; do
    for names in 0 1; do
        flags="-DGHJ_MAX_JOINTS=$joints"
        [ "$names" = 1 ] && flags="$flags -DWITH_NAMES"
        # shellcheck disable=SC2086
        "$cc" -mmcu="$mcu" -std=c99 -Os -Wall -Wextra -Wpedantic -Werror -ffunction-sections -fdata-sections \
            -Wl,--gc-sections $flags -I"$cdir" "$cdir/tools/avr_ram.c" "$cdir/ghjoints.c" -o "$tmp/a.elf"
        total=$(ram "$tmp/a.elf")
        d=$(symsize "$tmp/a.elf" dec)
        p=$(symsize "$tmp/a.elf" pkt)
        if [ "$names" = 1 ]; then what="with ghj_result_name()"; else what="decoding only"; fi
        echo "GHJ_MAX_JOINTS=$joints, $what: $total bytes = ghj_decoder $d + ghj_packet $p + other $((total - d - p))"
    done
done
