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
CFLAGS = ("-std=c11", "-O2", "-Wall", "-Wextra", "-Werror", "-Wshadow", "-Wdouble-promotion")

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


if __name__ == "__main__":
    for name in PROGRAMS:
        print(build(name))
