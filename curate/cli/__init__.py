"""``curate`` command line: :func:`main`.

The flags are bound to config fields in :mod:`curate.cli.flags` (options are declared once, in the config
dataclasses), the parser is :mod:`curate.cli.parser`, and each command is a thin function of
:mod:`curate.cli.commands`; this module runs a command and turns every error into one line (an unexpected one: one
line, the trace in a file).
"""

from __future__ import annotations

import errno
import logging
import sys
from pathlib import Path

from curate.cli.commands import CliError
from curate.cli.flags import COMMAND_OPTS
from curate.cli.parser import ALL, COMMANDS, _base_for, _command_of, _negative_values, build_parser

__all__ = ["ALL", "COMMANDS", "COMMAND_OPTS", "CliError", "build_parser", "main", "_base_for"]


def main(argv: list[str] | None = None) -> int:
    argv = _negative_values(list(sys.argv[1:] if argv is None else argv))
    try:
        args = build_parser(_command_of(argv)).parse_args(argv)
    except SystemExit as e:  # --help, --version (0) or a one-line usage error (2)
        return e.code if isinstance(e.code, int) else 2
    logging.basicConfig(level=logging.DEBUG if args.verbose else logging.WARNING,
                        format="%(levelname)s %(name)s: %(message)s")
    from curate.core import signals
    signals.install(f"curate {args.command}")   # SIGTERM and SIGHUP stop curate as Ctrl-C does
    try:
        return args.func(args)
    except CliError as e:
        print(f"curate {args.command}: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt as e:       # Ctrl-C, or SIGTERM / SIGHUP (curate.core.signals.Terminated)
        word, code = signals.said(e)
        if signals.unwound():            # else curate's watcher says it, ending the process
            print(f"curate {args.command}: {word}", file=sys.stderr)
        return code
    except OSError as e:
        if e.errno in (errno.EACCES, errno.EPERM, errno.EROFS) and e.filename:
            print(f"curate {args.command}: error: {denied(e)}", file=sys.stderr)
            return 2
        if e.errno != errno.ENOSPC:
            return _internal_error(args.command, e)
        print(f"curate {args.command}: error: the disk is full: no space left writing {e.filename or 'a file'}; "
              "free some space, then run the same command again (what finished is kept, nothing half-written is "
              "taken for finished)", file=sys.stderr)
        return 2
    except Exception as e:  # noqa: BLE001 - an internal error: one line, the trace in a file
        return _internal_error(args.command, e)


def denied(e: OSError) -> str:
    """What a permission error says: the file, or the folder above it that cannot be entered or read, and why."""
    import os
    p = Path(e.filename)
    if e.errno == errno.EROFS:
        return f"{p}: the file system is read-only: curate cannot write there; choose another --out"
    blocked = next((d for d in reversed(p.parents) if os.path.isdir(d) and not os.access(d, os.R_OK | os.X_OK)), None)
    if blocked is not None:
        return (f"{blocked}: cannot read this folder (permission denied): give it back read permission "
                f"(chmod u+rwx {blocked}), then run again")
    how = "cannot write it" if os.path.exists(p) and os.access(p, os.R_OK) else "cannot read it"
    return f"{p}: permission denied ({how}): give it back the permission (chmod u+rw {p}), then run again"


def _internal_error(command: str, e: BaseException) -> int:
    """An error curate did not expect: one line, the trace in a file; exit status 1."""
    log = _crash_log(e)
    print(f"curate {command}: internal error: {type(e).__name__}: {str(e).splitlines()[0] if str(e) else ''} "
          f"(full trace in {log})", file=sys.stderr)
    return 1


def _crash_log(exc: BaseException) -> Path:
    """Write the traceback of an unexpected error to a file; returns its path."""
    import tempfile
    import time
    import traceback
    p = Path(tempfile.gettempdir()) / f"curate-error-{time.strftime('%Y%m%d-%H%M%S')}-{__import__('os').getpid()}.log"
    p.write_text("".join(traceback.format_exception(type(exc), exc, exc.__traceback__)))
    return p
