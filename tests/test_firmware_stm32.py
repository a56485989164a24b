"""The reference firmware cross-compiled for the STM32F429 (Cortex-M4F) with arm-none-eabi-gcc.

Builds the ELF and the flashable .bin from the same core as the host build, reports their sizes,
and checks what makes an image bootable and the core fit for the MCU: the vector table at the start
of flash (initial stack pointer at the top of SRAM, a Thumb reset handler inside the image), no
double-precision soft-float helpers (the core is single-precision for the FPv4-SP FPU), and the
image within the part's flash and RAM.
"""

from __future__ import annotations

import struct
import subprocess

import pytest

from robot.firmware.build import CompilerMissingError, arm_tool, build_stm32, section_sizes

FLASH_START, FLASH_APP_SIZE = 0x0800_0000, 1920 * 1024  # the last 128 KB sector holds the parameters
RAM_START, RAM_SIZE = 0x2000_0000, 192 * 1024


@pytest.fixture(scope="module")
def elf(tmp_path_factory: pytest.TempPathFactory):
    try:
        return build_stm32(tmp_path_factory.mktemp("stm32f429"))
    except CompilerMissingError as exc:
        pytest.skip(f"the STM32F429 build needs arm-none-eabi-gcc: {exc}")


def test_image_boots_from_its_vector_table(elf) -> None:
    image = elf.with_suffix(".bin").read_bytes()
    initial_sp, reset = struct.unpack_from("<II", image)
    assert initial_sp == RAM_START + RAM_SIZE
    assert reset & 1, "the reset vector must be a Thumb address"
    assert FLASH_START < reset - 1 < FLASH_START + len(image)
    symbols = subprocess.run([arm_tool("nm"), str(elf)], capture_output=True, text=True, check=True).stdout
    addr = {
        line.split()[2]: int(line.split()[0], 16) for line in symbols.splitlines() if len(line.split()) == 3
    }
    assert addr["Reset_Handler"] == reset - 1
    assert addr["SysTick_Handler"] | 1 == struct.unpack_from("<I", image, 15 * 4)[0]  # the 1 ms tick


def test_core_is_single_precision(elf) -> None:
    symbols = subprocess.run([arm_tool("nm"), str(elf)], capture_output=True, text=True, check=True).stdout
    soft_double = sorted(
        {s.split()[-1] for s in symbols.splitlines() if "__aeabi_d" in s or "__aeabi_f2d" in s}
    )
    assert not soft_double, f"double-precision arithmetic crept into the firmware: {soft_double}"


def test_size_report_fits_the_stm32f429(elf, record_property) -> None:
    sizes = section_sizes(elf)
    record_property("stm32f429_sizes", sizes)
    print(f"STM32F429 firmware: flash {sizes['flash']} B (text {sizes['text']}, data {sizes['data']}), "
          f"RAM {sizes['ram']} B (data {sizes['data']}, bss {sizes['bss']})")  # fmt: skip
    assert sizes["flash"] <= FLASH_APP_SIZE and sizes["ram"] <= RAM_SIZE
    assert len(elf.with_suffix(".bin").read_bytes()) == sizes["flash"]
