"""The ``sns-np`` command.

Each subcommand lives in a small function ``_cmd_<name>(args)``; errors in the input (files,
options, meshes) are reported as one line on stderr with a non-zero exit status.
"""

from __future__ import annotations

import argparse
import sys

from ._version import __version__


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="sns-np",
        description="Spherical Neural Surfaces: fit genus-0 meshes with a hand-differentiated "
        "network and compute their differential geometry without meshing.",
    )
    parser.add_argument("--version", action="version", version=f"sns-np {__version__}")
    parser.add_subparsers(dest="command", metavar="COMMAND")
    return parser


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if getattr(args, "command", None) is None:
        parser.print_help()
        return 0
    try:
        return int(args.func(args) or 0)
    except (ValueError, OSError) as exc:
        print(f"sns-np {args.command}: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
