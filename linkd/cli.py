"""The `linkd` command line: one sub-command per module in `linkd.commands`.

Bad input (an `InputError`, or a usage error) prints one line and exits with status 2;
heavy libraries are imported by each command only when it runs.
"""

from __future__ import annotations

import argparse
import importlib
import os
import pkgutil
import signal
import sys
import textwrap

from linkd import __version__
from linkd.errors import InputError
from linkd.termination import Terminated, sigterm_raises

EPILOG = """\
start here:
  linkd design CURVE.csv    a verified linkage tracing your curve (see linkd design -h)
  linkd view CURVE-design   watch it move

`linkd COMMAND -h` explains each command."""

ORDER = ("design", "export", "verify", "validate", "trace", "view", "dataset", "train", "eval",
         "bench")  # fmt: skip


def command_names() -> list[str]:
    """Modules of `linkd.commands`, in the order the help lists them."""
    import linkd.commands

    found = [m.name for m in pkgutil.iter_modules(linkd.commands.__path__)]
    rank = {name: k for k, name in enumerate(ORDER)}
    return sorted(found, key=lambda name: (rank.get(name, len(ORDER)), name))


class HelpFormatter(argparse.RawDescriptionHelpFormatter):
    """Descriptions and epilogs keep their line breaks; every option with a default value
    shows it, unless its help already says what it defaults to."""

    def _get_help_string(self, action: argparse.Action) -> str | None:
        text = action.help or ""
        default = action.default
        if "default" in text or default in (None, argparse.SUPPRESS) or isinstance(default, bool):
            return action.help
        return f"{text} (default: %(default)s)"


class _Parser(argparse.ArgumentParser):
    """argparse with one-line usage errors (exit status 2) and defaults shown in the help."""

    def __init__(self, *args, **kwargs) -> None:
        kwargs.setdefault("formatter_class", HelpFormatter)
        super().__init__(*args, **kwargs)

    def error(self, message: str) -> None:  # type: ignore[override]
        print(f"{self.prog}: error: {message}", file=sys.stderr)
        raise SystemExit(2)


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="linkd", description="Design, export and verify planar linkages.",
                     epilog=EPILOG)  # fmt: skip
    parser.add_argument("--version", action="version", version=f"linkd {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser,
                                title="commands", metavar="COMMAND")  # fmt: skip
    for name in command_names():
        importlib.import_module(f"linkd.commands.{name}").register(sub)
    for action in sub._choices_actions:  # each command's help opens with its one-line summary
        command = sub.choices[action.dest]
        command.description = command.description or textwrap.fill(action.help, 78)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        with sigterm_raises():
            return int(args.run(args) or 0)
    except InputError as exc:
        print(f"linkd: error: {exc}", file=sys.stderr)
        return 2
    except Terminated:
        print("linkd: terminated", file=sys.stderr)
        return 128 + signal.SIGTERM
    except KeyboardInterrupt:
        print("linkd: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # the reader went away (`| head`): the rest goes nowhere, quietly
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 128 + signal.SIGPIPE


if __name__ == "__main__":
    sys.exit(main())
