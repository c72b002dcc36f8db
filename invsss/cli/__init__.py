"""The ``invsss`` command line.

Each subcommand is a module with two functions: ``add_parser(subparsers)``, which
declares its arguments and sets ``func=run``, and ``run(args, stop)``, which does
the work and returns an exit code (:mod:`.render`, :mod:`.fit`, :mod:`.export`,
:mod:`.sweep`, :mod:`.scene`, :mod:`.profile`). :func:`build_parser` registers
them with one line each; :mod:`.report` draws the fit's report page and
:mod:`.progress` its progress line.

Exit codes, all without a traceback:

* 0: done;
* 1: the work was done but its output could not be written (the fit's estimate
  is then saved elsewhere and the message says where), or a sweep ran to its
  end but some of its trials failed (each failure is in ``sweep-report``);
* 2: bad input, reported as ``invsss: error: <message>`` (an
  :class:`~invsss.validation.InvalidInputError`), an output directory that
  already holds a result or an output file that is already there
  (``--overwrite``), or an output directory in use by another run;
* 130 / 143: interrupted by SIGINT (Ctrl-C) / SIGTERM (:mod:`invsss.runtime.interrupts`).
  ``fit`` then writes the best estimate so far, marked ``"interrupted": true``,
  when at least one solver step has finished.
"""

from __future__ import annotations

import argparse
import os
import signal
import sys
import warnings

from .. import __version__
from ..runtime.determinism import use_deterministic_scheduler
from ..runtime.interrupts import Interrupted, StopSignals, command_finished
from ..validation import InvalidInputError, did_you_mean
from . import export, fit, profile, render, scene, sweep

__all__ = ["build_parser", "main"]


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="invsss",
        description="Differentiable inverse rendering of screen-space subsurface scattering.",
    )
    parser.add_argument("--version", action="version", version=f"invsss {__version__}")
    subparsers = parser.add_subparsers(title="commands", metavar="COMMAND")
    # One registration line per subcommand, in the order `invsss --help` lists them.
    render.add_parser(subparsers)
    fit.add_parser(subparsers)
    export.add_parser(subparsers)
    sweep.add_parser(subparsers)
    scene.add_parser(subparsers)
    profile.add_parser(subparsers)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run the command line with ``argv`` (default ``sys.argv[1:]``); return the exit code."""
    # Before JAX computes anything: XLA reads the flag when its backend starts.
    use_deterministic_scheduler()
    parser = build_parser()
    unknown = _unknown_option(parser, sys.argv[1:] if argv is None else argv)
    if unknown is not None:
        command, line = unknown
        command.print_usage(sys.stderr)
        print(line, file=sys.stderr)
        return 2
    try:
        args = parser.parse_args(argv)
    except SystemExit as exit_:  # --help, --version, or a usage error argparse printed
        return exit_.code if isinstance(exit_.code, int) else 2
    if not hasattr(args, "func"):
        parser.print_usage(sys.stderr)
        print("invsss: error: a command is required", file=sys.stderr)
        return 2
    stop = StopSignals()
    try:
        with warnings.catch_warnings(), stop:
            warnings.showwarning = _show_warning
            # A library's notice of its own future changes is for developers:
            # on a GPU, JAX's "Pallas Triton backend is deprecated" (docs/gpu.md)
            # otherwise reached every command as a warning the user can do nothing about.
            warnings.filterwarnings("ignore", category=DeprecationWarning, module=_LIBRARY_MODULES)
            _use_compile_cache(args)
            return args.func(args, stop)
    except InvalidInputError as err:
        print(f"invsss: error: {err}", file=sys.stderr)
        return 2
    except Interrupted as interrupt:
        # A signal outside the fit (reading, rendering): nothing to keep.
        return _interrupted(interrupt.signum)
    except Exception:
        # Interrupted raised inside a library's import or callback can come out as
        # another exception (a C extension's failed initialisation is an ImportError):
        # once it has been raised, whatever ends the command is that signal.
        if not stop.raised or stop.signum is None:  # raised implies a signum: the second test is for mypy
            raise
        return _interrupted(stop.signum)
    finally:
        command_finished()  # a signal from here on: one line, no traceback


def _unknown_option(parser: argparse.ArgumentParser, argv: list[str]) -> tuple[argparse.ArgumentParser, str] | None:
    """The command's parser and a one-line error for the first ``--option`` it does not
    know, with the closest one it does; None if there is none (or no command).

    argparse would report it only after the required options (``--output X`` was
    answered with "required: --out"), and at the top level, without a suggestion.
    """
    commands = next((a.choices for a in parser._actions if isinstance(a, argparse._SubParsersAction)), {})
    if not argv or argv[0] not in commands:
        return None
    command = commands[argv[0]]
    known = list(command._option_string_actions)
    words = argv[1:argv.index("--")] if "--" in argv else argv[1:]
    if any(word == "-h" or (len(word) > 2 and "--help".startswith(word)) for word in words):
        return None  # argparse prints the help whatever else is on the line
    for word in words:
        if " " in word:
            continue  # argparse takes a word with a space as a value, whatever it starts with
        name = word.split("=", 1)[0]
        # argparse also takes a unique prefix of an option (--overw for --overwrite).
        if name.startswith("--") and name not in known and not any(k.startswith(name) for k in known):
            return command, f"invsss {argv[0]}: error: unrecognized option {name}{did_you_mean(name, known)}"
    return None


def _interrupted(signum: int) -> int:
    print(f"invsss: interrupted ({signal.Signals(signum).name}); nothing written", file=sys.stderr)
    return 128 + signum


def _use_compile_cache(args: argparse.Namespace) -> None:
    """JAX's persistent compilation cache for the commands that compile (those with --no-cache)."""
    if not hasattr(args, "no_cache"):
        return
    if args.no_cache:
        # Through the environment, so that a sweep's worker processes see it too.
        os.environ["INVSSS_NO_CACHE"] = "1"
        return
    from ..runtime.compile_cache import enable_compile_cache

    enable_compile_cache()


#: The modules whose DeprecationWarnings the command line drops (a regular
#: expression on the warning's module, as ``warnings.filterwarnings`` takes it).
_LIBRARY_MODULES = r"(jax|jaxlib|equinox|optimistix|lineax|jaxtyping)(\.|$)"


def _show_warning(message, category, filename, lineno, file=None, line=None):
    # Library warnings reach a command-line user as one line, without a source location.
    print(f"invsss: warning: {message}", file=sys.stderr)


if __name__ == "__main__":
    sys.exit(main())
