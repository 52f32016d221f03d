"""Commands made of named targets (``gyrostar eval starcount``, ``gyrostar sim frame``…).

Each target is a module exposing ``HELP`` (one line), ``configure(parser)`` and
``run(args) -> int``. Target modules must be cheap to import (heavy imports go inside
``run``) so that ``gyrostar --help`` stays fast. A target whose module is missing or
fails to import is still listed, and running it explains why (exit code 4).
"""

from __future__ import annotations

import argparse
import importlib
import logging

from ..errors import NotAvailableError

log = logging.getLogger(__name__)


def registered_targets(command: str) -> dict[str, str]:
    """Targets of ``command`` that the distribution registers as entry points (group
    ``gyrostar.targets``, name ``COMMAND.TARGET``, value the module): how the flight CLI
    reaches ground code (simulator, evaluations, calibration front ends) without importing it."""
    from importlib.metadata import entry_points

    return {ep.name.split(".", 1)[1]: ep.value for ep in sorted(entry_points(group="gyrostar.targets"))
            if ep.name.startswith(command + ".")}


def run_registered(command: str, args) -> int:
    """Run ``command`` through the module registered for it (entry-point group
    ``gyrostar.commands``); exit 4 when this build has none."""
    from importlib.metadata import entry_points

    found = [ep.value for ep in entry_points(group="gyrostar.commands") if ep.name == command]
    if not found:
        raise NotAvailableError(f"'{command}' is not available in this build (no gyrostar.commands entry point: "
                                "reinstall with pip install -e .)")
    try:
        module = importlib.import_module(found[0])
    except ImportError as exc:
        raise NotAvailableError(f"'{command}' is not available in this build ({found[0]}: {exc})") from exc
    return module.run(args)


def add_verbosity(parser) -> None:
    """-v/-vv and -q on ``parser``: accepted at every level of the command line (before or
    after a command or target; the innermost level given wins); absent unless given
    (``verbose`` 0 then)."""
    parser.add_argument("-v", "--verbose", action="count", default=argparse.SUPPRESS,
                        help="more log output (-vv debug)")
    parser.add_argument("-q", "--quiet", action="store_const", const=-1, dest="verbose", default=argparse.SUPPRESS,
                        help="errors only, no progress bars")


def add_targets(parser, targets: dict[str, str], dest: str) -> None:
    """Register one sub-parser per target module (name -> dotted module path)."""
    sub = parser.add_subparsers(dest=dest, metavar="TARGET", required=True)
    for name, module_path in targets.items():
        try:
            module = importlib.import_module(module_path)
        except ImportError as exc:
            p = sub.add_parser(name, help=f"(not available: {exc})")
            p.set_defaults(_target_run=_unavailable(name, module_path, exc))
            continue
        p = sub.add_parser(name, help=module.HELP, description=module.HELP)
        add_verbosity(p)
        module.configure(p)
        p.set_defaults(_target_run=module.run, _parser=p)


def run_target(args) -> int:
    return args._target_run(args)


def _unavailable(name: str, module_path: str, exc: Exception):
    def run(args) -> int:
        raise NotAvailableError(f"'{name}' is not available in this build ({module_path}: {exc})")
    return run
