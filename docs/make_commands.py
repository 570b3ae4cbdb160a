"""Write docs/commands.md from the `sunsim` argument parser, so the reference never drifts from the code.

    .venv/bin/python docs/make_commands.py          # rewrites docs/commands.md beside this file
"""
import argparse
import os
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.dirname(HERE))

from simcore.cli import build_parser  # noqa: E402

HEADER = """# sunsim commands

Generated from the argument parser by `docs/make_commands.py`; do not edit by hand. Every command takes
`--debug` (a user error's traceback) and most take `--json`. A user mistake gets one line on stderr and exit
status 2 before anything is written; any other error is a bug in sunsim and shows its traceback.
"""


def render(parser=None):
    """Return the Markdown reference of every subcommand of ``parser`` (default: sunsim's)."""
    parser = parser or build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    helps = {c.dest: c.help for c in sub._choices_actions}
    out = [HEADER]
    for name, p in sub.choices.items():
        p.formatter_class = lambda prog: argparse.HelpFormatter(prog, width=110, max_help_position=34)
        out.append(f"## `sunsim {name}`\n\n{helps.get(name, '')}\n\n```\n{p.format_help().rstrip()}\n```\n")
    return "\n".join(out)


if __name__ == "__main__":
    path = os.path.join(HERE, "commands.md")
    with open(path, "w") as fh:
        fh.write(render())
    print(f"wrote {path}")
