"""The code examples in docs/c-decoder.md compile against ghjoints.h as it is: the C ones with the project's
strict warnings, the Arduino one as C++. Only the board's own functions are stubbed (declared, never run)."""
from __future__ import annotations

import re
import shutil
import subprocess
from pathlib import Path

import pytest

from tests.clients.c_build import C_DECODER_DOC, C_DIR, compile_c, doc_code_blocks, require_compiler

# What the examples call but a board support package provides.
C_BOARD = """\
#include <stddef.h>
#include <stdint.h>
typedef struct { volatile uint32_t RDR; } ghj_doc_usart;
extern ghj_doc_usart *USART1;
void board_init(void);
void uart_init(unsigned long baud);
void led_blink(unsigned fault);
void idle(void);
void arm_move_to(int16_t x, int16_t y, int16_t z);
"""
CPP_BOARD = """\
struct ghj_doc_serial { void begin(long); int available(); int read(); };
extern ghj_doc_serial Serial;
struct ghj_doc_servo { void write(long); };
extern ghj_doc_servo head_servo;
long map(long, long, long, long, long);
"""


def test_c_examples_compile(tmp_path: Path) -> None:
    """The UART example and the USB CDC and UDP ones after it form one program (the other two use the first's
    dec and pkt); handle_packet is the reader's own."""
    cc = require_compiler()
    blocks = doc_code_blocks("c")
    assert len(blocks) == 3, "docs/c-decoder.md's C examples changed: update this test"
    src = tmp_path / "doc_examples.c"
    src.write_text(C_BOARD + blocks[0] + "\nvoid handle_packet(const ghj_packet *p);\n" + blocks[1] + blocks[2])
    compile_c(cc, tmp_path / "doc_examples.o", [src], ["-c"])


def test_arduino_example_compiles_as_cpp(tmp_path: Path) -> None:
    cxx = shutil.which("g++") or shutil.which("clang++")
    if cxx is None:
        pytest.skip("no C++ compiler for the Arduino example")
    blocks = doc_code_blocks("cpp")
    assert len(blocks) == 1, "docs/c-decoder.md's Arduino example changed: update this test"
    src = tmp_path / "sketch.cpp"
    src.write_text(CPP_BOARD + blocks[0])
    proc = subprocess.run([cxx, "-std=c++11", "-Wall", "-Wextra", "-Werror", f"-I{C_DIR}", "-c", str(src), "-o",
                           str(tmp_path / "sketch.o")], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr


def avr_uart_rate(baud: int, f_cpu: int = 16_000_000) -> float:
    """The rate an AVR UART runs when Arduino's AVR core (HardwareSerial::begin) is asked for ``baud``: double
    speed (U2X), divisor n = (f_cpu / 4 / baud - 1) / 2 in integer arithmetic, rate f_cpu / (8 (n + 1)); normal
    speed, f_cpu / (16 (n + 1)), for 57600 at 16 MHz (the old bootloaders' rate) and where n would not fit."""
    n = (f_cpu // 4 // baud - 1) // 2
    if (f_cpu == 16_000_000 and baud == 57600) or n > 4095:
        n = (f_cpu // 8 // baud - 1) // 2
        return f_cpu / (16 * (n + 1))
    return f_cpu / (8 * (n + 1))


@pytest.mark.parametrize("baud, error", [(115200, 0.021), (921600, 0.085), (1_000_000, 0.0), (500_000, 0.0),
                                         (57600, 0.021), (9600, 0.002)])
def test_avr_uart_rate_matches_the_docs_figures(baud: int, error: float) -> None:
    # the figures docs/c-decoder.md quotes (2.1 %, 8.5 %, exact for 500000 and 1000000), and two of the 328P
    # datasheet's baud table for 16 MHz (57600 at normal speed, UBRR 16: 2.1 %; 9600 double speed, UBRR 207: 0.2 %)
    assert avr_uart_rate(baud) / baud - 1 == pytest.approx(error, abs=0.0006)


def test_arduino_example_s_baud_runs_on_a_16_mhz_avr() -> None:
    """The Arduino example is for an Uno-class board (its RAM figures are the ATmega328P's), whose UART cannot
    make 921600: it ran 1 000 000, 8.5 % off a USB-serial chip that makes 921600, and its frames failed.
    A UART samples each bit in its middle, the stop bit 9.5 bits after the start edge, so half a bit of slack
    over 9.5 bits (5 %) is lost in all; 2.5 % leaves the rest to the sender's clock and the sampling step."""
    (sketch,) = doc_code_blocks("cpp")
    (baud,) = (int(b) for b in re.findall(r"Serial\.begin\((\d+)\)", sketch))
    assert abs(avr_uart_rate(baud) / baud - 1) < 0.025, f"Serial.begin({baud}) on a 16 MHz AVR"
    doc = C_DECODER_DOC.read_text()
    assert f"baud={baud}" in sketch and f"Use `baud={baud}` in the sink URL" in doc  # the sink must match it
