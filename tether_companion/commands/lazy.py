"""Sub-commands whose modules are imported only when they run.

``tether-companion --help`` lists every command's one-line ``HELP``, but importing a command
module pulls in its subsystem (numpy, scipy, pymavlink, the simulator...), which costs
seconds on a small board. :func:`add_lazy_subcommands` therefore reads each module's
``HELP`` string from its source (``HELP = "..."`` at module level, a literal) and imports
only the module of the command actually given on the command line, whose ``add_arguments``
then builds the full sub-parser. The same holds for the benchmarks under ``bench``.
"""

from __future__ import annotations

import argparse
import ast
import importlib
import importlib.util
from collections.abc import Sequence


def help_line(module_name: str) -> str:
    """The module-level ``HELP`` literal of ``module_name``, read without importing it.

    Raises
    ------
    LookupError
        When the module has no literal ``HELP`` assignment (a programming error).
    """
    spec = importlib.util.find_spec(module_name)
    if spec is None or spec.origin is None:
        raise LookupError(f"no module {module_name}")
    with open(spec.origin, encoding="utf-8") as source:
        tree = ast.parse(source.read(), filename=spec.origin)
    for node in tree.body:
        if (
            isinstance(node, ast.Assign)
            and len(node.targets) == 1
            and isinstance(node.targets[0], ast.Name)
            and node.targets[0].id == "HELP"
        ):
            return str(ast.literal_eval(node.value))
    raise LookupError(f"{module_name} has no literal HELP")


def selected(argv: Sequence[str], names: Sequence[str]) -> str | None:
    """The first of ``names`` that is the first positional word of ``argv`` (else None)."""
    for word in argv:
        if word.startswith("-"):
            continue
        return word if word in names else None
    return None


def add_lazy_subcommands(
    sub: argparse._SubParsersAction,
    package: str,
    names: Sequence[str],
    argv: Sequence[str],
    default_key: str,
) -> None:
    """One sub-parser per name of ``package``; only the one selected by ``argv`` is imported.

    The selected module's ``add_arguments`` fills its sub-parser and its ``run`` is stored as
    the ``default_key`` default; the others get their help line only (they are never parsed).
    The words of ``argv`` after the command's name are the sub-parser's ``command_argv``
    default, for a command with sub-commands of its own (``bench NAME``).
    """
    chosen = selected(argv, names)
    rest = list(argv[list(argv).index(chosen) + 1 :]) if chosen is not None else []
    for name in names:
        module_name = f"{package}.{name}"
        if name != chosen:
            text = help_line(module_name)
            sub.add_parser(name, help=text, description=text)
            continue
        module = importlib.import_module(module_name)
        parser = sub.add_parser(name, help=module.HELP, description=module.HELP)
        parser.set_defaults(command_argv=rest)
        module.add_arguments(parser)
        parser.set_defaults(**{default_key: module.run})
