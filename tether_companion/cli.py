"""The ``tether-companion`` command line: one entry point, one module per command.

Each command lives in ``tether_companion.commands.<name>`` and exposes ``HELP`` (one line),
``add_arguments(parser)`` and ``run(args) -> int``. Usage and config errors exit with code 2
and a one-line message, never a traceback.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from typing import NoReturn

from tether_companion import __version__
from tether_companion.commands.lazy import add_lazy_subcommands
from tether_companion.config import ConfigError
from tether_companion.errors import InputError

COMMANDS: tuple[str, ...] = ("demo", "run", "replay", "simulate", "bench", "emulate", "sysid")
"""Command names, in the order ``--help`` lists them; module ``commands/<name>.py`` each."""

EXIT_USAGE = 2
EXIT_INTERRUPTED = 130


class OneLineParser(argparse.ArgumentParser):
    """argparse with a one-line error (what is wrong and where the help is), exit code 2.

    argparse's own error prints the whole usage block first, which systemd's journal and
    ``systemctl status`` show as several lines that hide the error.
    """

    def error(self, message: str) -> NoReturn:
        self.exit(EXIT_USAGE, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def build_parser(argv: Sequence[str] = ()) -> argparse.ArgumentParser:
    """The argument parser with one sub-parser per command; only the command named in
    ``argv`` is imported and given its options (``--help`` alone imports none)."""
    parser = OneLineParser(
        prog="tether-companion",
        description="Localise a tethered drone from its tether's pull and feed the position "
        "to ArduPilot or PX4 over MAVLink.",
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    add_lazy_subcommands(sub, "tether_companion.commands", COMMANDS, argv, "run")
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; returns the process exit code."""
    argv = sys.argv[1:] if argv is None else list(argv)
    parser = build_parser(argv)
    args = parser.parse_args(argv)
    try:
        return int(args.run(args) or 0)
    except (ConfigError, InputError) as exc:
        print(f"tether-companion {args.command}: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt:
        print(f"tether-companion {args.command}: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED


if __name__ == "__main__":
    sys.exit(main())
