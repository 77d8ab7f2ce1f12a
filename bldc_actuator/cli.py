"""``bldc-actuator`` command line: wires the subcommands, each of which lives in its own module.

A subcommand module exposes ``register(subparsers)`` which adds its parser and sets
``func=<callable(args) -> int>`` as the parser default.
"""

from __future__ import annotations

import argparse
import importlib
import sys

#: modules that provide subcommands, in the order ``--help`` lists them
SUBCOMMAND_MODULES = (
    "bldc_actuator.convert",
    "bldc_actuator.simulate",
    "bldc_actuator.demo",
    "bldc_actuator.record_info",
    "bldc_actuator.diagnosis.cli",
    "bldc_actuator.fleet.cli",
    "bldc_actuator.mujoco.export",
)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="bldc-actuator",
        description="Virtual BLDC actuator: datasheet conversion, simulation, recordings, diagnosis.",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in SUBCOMMAND_MODULES:
        try:
            module = importlib.import_module(name)
        except ModuleNotFoundError as exc:  # a subcommand not built yet must not break the others
            if exc.name and exc.name.startswith("bldc_actuator"):
                continue
            raise
        module.register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    return int(args.func(args) or 0)


if __name__ == "__main__":
    sys.exit(main())
