"""The ``pickplace`` console script and ``python -m pickplace``: the stop-signal handlers first,
then the CLI (:func:`pickplace.cli.console`).

The CLI's imports (MuJoCo, numpy, the package) take seconds on a loaded machine; with the
handlers installed before them a Ctrl-C, SIGTERM or SIGHUP then is noted and handled as one
during set-up (a summary, 128 + N), never a KeyboardInterrupt traceback or a silent kill. Only
the interpreter's own start-up comes before.
"""

from __future__ import annotations

from typing import NoReturn

from pickplace.signals import InterruptHandler


def console_main() -> NoReturn:
    """Install the stop-signal handlers, then run the command line (never returns)."""
    stop = InterruptHandler().install()
    from pickplace.cli import console

    console(stop)


if __name__ == "__main__":
    console_main()
