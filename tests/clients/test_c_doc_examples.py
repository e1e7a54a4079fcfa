"""The code examples in docs/c-decoder.md compile against ghjoints.h as it is: the C ones with the project's
strict warnings, the Arduino one as C++. Only the board's own functions are stubbed (declared, never run)."""
from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import pytest

from tests.clients.c_build import C_DIR, compile_c, doc_code_blocks, require_compiler

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
