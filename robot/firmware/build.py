"""Build the C firmware programs with the system C compiler (``cc``): tests and ``make`` use this.

Only the compiler is needed (no make, no cmake): each program is one ``cc`` call over its sources.
Outputs go to a build directory and are rebuilt when any source is newer than the binary.
"""

from __future__ import annotations

import os
import shutil
import subprocess
from pathlib import Path

FIRMWARE_DIR = Path(__file__).resolve().parent
INCLUDE_DIR = FIRMWARE_DIR / "include"
CORE_DIR = FIRMWARE_DIR / "core"
WARNINGS = ("-Wall", "-Wextra", "-Werror", "-Wshadow", "-Wdouble-promotion")
CFLAGS = ("-std=c11", "-O2", *WARNINGS)

PROGRAMS: dict[str, tuple[str, ...]] = {
    # host test program for the protocol header
    "protocol_vectors": ("tests/protocol_vectors.c",),
    # the firmware core on a pseudo-terminal with a simulated motor/encoder plant
    "navdeck_fw_host": (
        "core/nd_core.c",
        "core/nd_control.c",
        "core/nd_params.c",
        "host/plant.c",
        "host/hal_host.c",
        "host/main.c",
    ),
}


# The reference firmware for the STM32F429 (Cortex-M4F), built with Debian's gcc-arm-none-eabi.
STM32_SOURCES = (
    "core/nd_core.c",
    "core/nd_control.c",
    "core/nd_params.c",
    "board/stm32f429/startup.c",
    "board/stm32f429/hal_stm32.c",
    "board/stm32f429/main.c",
)
STM32_FLAGS = (
    "-mcpu=cortex-m4", "-mthumb", "-mfloat-abi=hard", "-mfpu=fpv4-sp-d16", "-Os", "-g",
    "-ffunction-sections", "-fdata-sections", "-nostartfiles", "--specs=nano.specs", "--specs=nosys.specs",
    "-Wl,--gc-sections",
)  # fmt: skip


class CompilerMissingError(RuntimeError):
    """No C compiler on PATH."""


def compiler() -> str:
    cc = os.environ.get("CC") or "cc"
    if shutil.which(cc) is None:
        raise CompilerMissingError(f"no C compiler: {cc!r} is not on PATH (install gcc or set CC)")
    return cc


def default_build_dir() -> Path:
    return FIRMWARE_DIR / "build" / "host"


def build(program: str, build_dir: Path | None = None) -> Path:
    """Compile ``program`` (a key of ``PROGRAMS``) if needed; return the executable's path."""
    sources = [FIRMWARE_DIR / s for s in PROGRAMS[program]]
    out_dir = build_dir or default_build_dir()
    out_dir.mkdir(parents=True, exist_ok=True)
    exe = out_dir / program
    deps = [*sources, *INCLUDE_DIR.glob("*.h"), *CORE_DIR.glob("*.h"), *(FIRMWARE_DIR / "host").glob("*.h")]
    if exe.exists() and all(d.stat().st_mtime <= exe.stat().st_mtime for d in deps):
        return exe
    tmp = exe.with_name(exe.name + f".{os.getpid()}.tmp")  # parallel test workers must not collide
    cmd = [
        compiler(),
        *CFLAGS,
        f"-I{INCLUDE_DIR}",
        f"-I{CORE_DIR}",
        *map(str, sources),
        "-o",
        str(tmp),
        "-lm",
    ]
    done = subprocess.run(cmd, capture_output=True, text=True, check=False)
    if done.returncode != 0:
        raise RuntimeError(f"building {program} failed:\n{' '.join(cmd)}\n{done.stderr}")
    os.replace(tmp, exe)
    return exe


def arm_tool(name: str) -> str:
    tool = f"arm-none-eabi-{name}"
    if shutil.which(tool) is None:
        raise CompilerMissingError(
            f"no {tool}: install Debian's gcc-arm-none-eabi (apt-get install gcc-arm-none-eabi)"
        )
    return tool


def build_stm32(build_dir: Path | None = None) -> Path:
    """Cross-compile the STM32F429 firmware: ``navdeck_fw_stm32f429.elf`` and ``.bin`` (to flash at
    0x08000000). Returns the ELF's path."""
    out_dir = build_dir or FIRMWARE_DIR / "build" / "stm32f429"
    out_dir.mkdir(parents=True, exist_ok=True)
    board = FIRMWARE_DIR / "board" / "stm32f429"
    elf = out_dir / "navdeck_fw_stm32f429.elf"
    cmd = [
        arm_tool("gcc"), "-std=c11", *WARNINGS, *STM32_FLAGS,
        f"-I{INCLUDE_DIR}", f"-I{CORE_DIR}", f"-I{board}",
        f"-T{board / 'stm32f429.ld'}", f"-Wl,-Map={out_dir / 'navdeck_fw_stm32f429.map'}",
        *(str(FIRMWARE_DIR / s) for s in STM32_SOURCES), "-o", str(elf),
    ]  # fmt: skip
    done = subprocess.run(cmd, capture_output=True, text=True, check=False)
    if done.returncode != 0:
        raise RuntimeError(f"building the STM32F429 firmware failed:\n{' '.join(cmd)}\n{done.stderr}")
    subprocess.run([arm_tool("objcopy"), "-O", "binary", str(elf), str(elf.with_suffix(".bin"))], check=True)
    return elf


def section_sizes(elf: Path) -> dict[str, int]:
    """``arm-none-eabi-size`` of the ELF: text (flash code + constants), data (flash and RAM), bss (RAM)."""
    out = subprocess.run([arm_tool("size"), str(elf)], capture_output=True, text=True, check=True).stdout
    text, data, bss = (int(v) for v in out.splitlines()[1].split()[:3])
    return {"text": text, "data": data, "bss": bss, "flash": text + data, "ram": data + bss}


if __name__ == "__main__":
    import sys

    targets = sys.argv[1:] or ["host"]
    if "host" in targets or "all" in targets:
        for name in PROGRAMS:
            print(build(name))
    if "stm32" in targets or "all" in targets:
        elf = build_stm32()
        print(elf, section_sizes(elf))
