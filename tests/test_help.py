"""`linkd ... --help` is enough to start: defaults shown, the curve format, runnable examples."""

import argparse
import shlex

import pytest

from linkd.cli import build_parser, main


def _commands() -> dict[str, argparse.ArgumentParser]:
    parser = build_parser()
    (sub,) = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    return dict(sub.choices)


def _help(args, capsys) -> str:
    with pytest.raises(SystemExit) as exit_:
        main([*args, "--help"])
    assert exit_.value.code == 0
    return capsys.readouterr().out


def test_design_help_shows_defaults_the_curve_format_and_examples(capsys):
    text = " ".join(_help(["design"], capsys).split())  # undo the line wrapping
    for default in ("(default: mm)", "(default: 512)", "(default: 0)", "(default: node)",
                    "(default: 30.0)", "(default: mjcf,stl)"):  # fmt: skip
        assert default in text
    assert 'one "x,y" point per row' in text and "metres" in text
    assert "<curve>-design" in text and "--force" in text


def test_every_default_is_shown_and_every_command_says_what_it_does(capsys):
    for name, command in _commands().items():
        text = " ".join(_help([name], capsys).split())
        assert command.description and " ".join(command.description.split()) in text
        for action in command._actions:
            default = action.default
            if (
                action.help
                and default not in (None, argparse.SUPPRESS)
                and not isinstance(default, bool)
            ):
                assert f"default: {default}" in text or "default" in action.help, (name, action)


def test_every_option_of_every_command_and_benchmark_has_help(capsys):
    commands = {(name,): command for name, command in _commands().items()}
    (targets,) = [a for a in commands[("bench",)]._actions
                  if isinstance(a, argparse._SubParsersAction)]  # fmt: skip
    commands |= {("bench", name): target for name, target in targets.choices.items()}
    for words, command in commands.items():
        text = " ".join(_help(list(words), capsys).split())
        for action in command._actions:
            if action.option_strings and action.help != argparse.SUPPRESS:
                assert action.help, (words, action.option_strings)
                default = action.default
                if default not in (None, argparse.SUPPRESS) and not isinstance(default, bool):
                    assert f"default: {default}" in text or "default" in action.help


def test_a_closed_pipe_ends_quietly():
    """`linkd ... | head`: the reader went away; no traceback, the usual broken-pipe status."""
    import os
    import subprocess
    import sys
    from pathlib import Path

    mechanism = Path(__file__).parents[1] / "assets" / "examples" / "jansen_leg.json"
    read, write = os.pipe()
    os.close(read)
    try:
        run = subprocess.run([sys.executable, "-m", "linkd.cli", "validate", str(mechanism)],
                             stdout=write, stderr=subprocess.PIPE, text=True)  # fmt: skip
    finally:
        os.close(write)
    assert run.returncode == 141 and run.stderr == "", run.stderr


def test_help_examples_are_valid_command_lines():
    examples = []
    for command in _commands().values():
        lines = (command.epilog or "").splitlines()
        examples += [line.strip() for line in lines if line.strip().startswith("linkd ")]
    assert any(line.startswith("linkd design ") for line in examples)
    for line in examples:
        args = build_parser().parse_args(shlex.split(line)[1:])
        assert callable(args.run)
