"""``gyrostar fw build``: build the firmware host program (and the ARM image, and run the C tests)."""

from __future__ import annotations

HELP = "build the head firmware: host program (default), --arm image, --test C unit tests"


def configure(parser) -> None:
    from ..cli.main import add_json

    parser.add_argument("--arm", action="store_true", help="also build the mps2-an385 ARM image")
    parser.add_argument("--test", action="store_true", help="also build and run the C unit tests")
    add_json(parser)


def run(args) -> int:
    from ..cli.output import emit
    from . import build

    result = {"host": str(build.host_binary_path())}
    lines = []
    build.build("host")
    lines.append(f"host program: {build.host_binary_path()}")
    if args.test:
        out = build.build("test")
        summary = [ln for ln in out.splitlines() if ln.startswith("gyrostar firmware tests")]
        result["tests"] = summary[-1] if summary else out.splitlines()[-1]
        lines.append(result["tests"])
    if args.arm:
        sizes = build.arm_sizes(build.build("arm"))
        result["arm"] = {"elf": str(build.arm_elf_path()), **sizes}
        lines.append(f"ARM image: {build.arm_elf_path()}  flash {sizes['flash_bytes']} B, static RAM "
                     f"{sizes['static_ram_bytes']} B (limits 65536 each)")
    emit(args, result, "\n".join(lines))
    return 0
