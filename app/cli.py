"""`squashcal` command line. Each subcommand lives in its own module, imported when it runs."""

from __future__ import annotations

import argparse
import importlib
import sys

# subcommand -> (module, one-line help). Each module has add_arguments(parser) and run(args) -> int.
COMMANDS: dict[str, tuple[str, str]] = {
    "calibrate": ("app.cli_calibrate", "calibrate a camera from one image"),
    "run": ("app.cli_service", "start the API and one worker (what `make run` does)"),
    "serve": ("app.cli_service", "start the API server alone"),
    "worker": ("app.cli_service", "start one worker process alone"),
    "migrate": ("app.cli_service", "apply database migrations"),
    "keys": ("app.cli_service", "manage API keys"),
}

# commands that use the tables: checked for a migrated database before they run, so that a fresh
# data dir gets the command to run instead of a traceback or a server answering 503 (`run`
# migrates by itself, `calibrate` uses no database)
NEEDS_SCHEMA = frozenset({"keys", "worker", "serve"})
# ... but these start while the database is unreachable: the API answers 503 with Retry-After
# until it is back (a database still starting, or restarted), and recovers by itself
START_WITHOUT_DATABASE = frozenset({"serve"})


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="squashcal", description=__doc__)
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name, (module_name, help_text) in COMMANDS.items():
        module = importlib.import_module(module_name)
        cmd = sub.add_parser(name, help=help_text, description=help_text)
        module.add_arguments(name, cmd)
        cmd.set_defaults(_module=module)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.command is None:
        parser.print_help()
        return 0
    if args.command in NEEDS_SCHEMA:
        from app.db.migrate import schema_problem
        from app.settings import get_settings

        problem = schema_problem(
            get_settings(), unreachable_ok=args.command in START_WITHOUT_DATABASE
        )
        if problem is not None:
            print(f"squashcal {args.command}: {problem}", file=sys.stderr)
            return 2
    return int(args._module.run(args.command, args))


if __name__ == "__main__":
    sys.exit(main())
