"""``gyrostar fw arm``: build the mps2-an385 image, print its sizes; ``--run`` serves it under QEMU."""

from __future__ import annotations

HELP = "build the Cortex-M3 image (QEMU mps2-an385), print flash/RAM sizes; --run starts it under QEMU"


def configure(parser) -> None:
    from ..cli.main import add_json

    parser.add_argument("--run", action="store_true", help="run the image under qemu-system-arm until Ctrl-C")
    parser.add_argument("--sensor", help="pixel file the image reads by semihosting (needed with --run)")
    parser.add_argument("--port", type=int, default=0, help="TCP port of the UART (default: a free port)")
    add_json(parser)


def run(args) -> int:
    import time

    from ..cli.output import emit
    from ..errors import ConfigError
    from . import build, qemu
    from .interrupt import sigterm_as_interrupt

    if args.run and not args.sensor:      # before the build: a usage error costs nothing
        raise ConfigError("--run needs --sensor FILE (a GSPX pixel file, see firmware/README.md)")
    sizes = build.arm_sizes(build.build("arm"))
    ok = sizes["flash_bytes"] <= sizes["flash_limit"] and sizes["static_ram_bytes"] <= sizes["ram_limit"]
    result = {"elf": str(build.arm_elf_path()), **sizes, "within_limits": ok}
    emit(args, result, f"{build.arm_elf_path()}\nflash {sizes['flash_bytes']} B / {sizes['flash_limit']}, static "
                       f"RAM {sizes['static_ram_bytes']} B / {sizes['ram_limit']} (pixel line buffer "
                       f"{sizes['line_buffer_bytes']} B and stack {sizes['stack_bytes']} B apart)")
    if not args.run:
        return 0 if ok else 1
    with sigterm_as_interrupt(), qemu.QemuHead(args.sensor, elf=build.arm_elf_path(), port=args.port or None) as q:
        print(f"gyrostar-head (mps2-an385 under QEMU): {q.url}", flush=True)
        while q.proc.poll() is None:   # Ctrl-C or SIGTERM: QEMU is stopped on the way out, exit 130
            time.sleep(0.5)
    return 1
