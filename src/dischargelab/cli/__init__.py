"""Command line interface: parse -> call the library -> print a table or JSON.

Every command accepts ``--json`` (JSON alone on stdout) and shows examples in
``--help``. Errors the user can fix (:class:`~dischargelab.errors.DischargelabError`
and usage errors) print one line on stderr and exit with status 2; any other
exception is a bug: its traceback is printed with a request to report it, and
the status is 1. ``DISCHARGELAB_DEBUG=1`` shows tracebacks for every error.

One module per command group, each a thin layer over the library
(:mod:`dischargelab.api` and the modules it names); what they share (option
types, consoles, JSON, error lines) is in :mod:`.common`:

- :mod:`.model`: fit, predict, curves, validate, presets, models
- :mod:`.missions`: endurance, report, demo
- :mod:`.examples`: examples (the example set into a folder)
- :mod:`.flightlogs`: convert, flight, autopilot-params, autopilot-script
- :mod:`.testers`: steps (battery testers' files)
- :mod:`.acquisition`: calibrate, acquire, virtual-device, demo-acquire
- :mod:`.serve`: serve (the web pages)
- :mod:`.logbook`: logbook add, packs, health, events, export, fit
"""

from __future__ import annotations

import os
import sys
import traceback

import click

from ..errors import DischargelabError
from . import acquisition, examples, flightlogs, logbook, missions, model, serve, testers
from .common import BUG_LINE, CONTEXT, cli_message, err, usage_line

__all__ = ["BUG_LINE", "app", "main"]

# The numerics of every command are small matrices (tens of columns): BLAS threads only
# wait for one another there, and on two shared cores the whole `fit` of three rates took
# 2-3x the time with them (benchmarks/fit_latency.py). Numpy loads only when a command runs
# (nothing above imports it), so this is before; a user's own setting wins.
for _threads in ("OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "OMP_NUM_THREADS"):
    os.environ.setdefault(_threads, "1")


@click.group(context_settings=CONTEXT)
@click.version_option(package_name="dischargelab")
def app() -> None:
    """Turn a battery discharge test into a battery model and a UAV endurance estimate.

    \b
    Typical use:
      dischargelab fit discharge.csv --cells 4 -o battery.json
      dischargelab predict battery.json --current 20 --cutoff 3.0
      dischargelab curves battery.json --currents 5,10,20 --cutoff 3.0 -o curves.png
      dischargelab demo
    """


for _group in (model, missions, examples, flightlogs, testers, acquisition, serve, logbook):
    for _command in _group.COMMANDS:
        app.add_command(_command)


def main(argv: list[str] | None = None) -> None:
    """Entry point of the ``dischargelab`` command.

    Exit status: 0 success, 2 an error the user can fix (one line on stderr),
    1 a bug (traceback and a request to report it), 130 interrupted; ``acquire``
    adds its own (see its ``--help``). ``DISCHARGELAB_DEBUG=1`` re-raises every
    error with its traceback.
    """
    debug = os.environ.get("DISCHARGELAB_DEBUG") == "1"
    try:
        code = app.main(args=argv, prog_name="dischargelab", standalone_mode=False)
    except click.ClickException as exc:
        err.print(f"error: {usage_line(exc)}", markup=False)
        sys.exit(2)
    except click.exceptions.Abort:
        err.print("aborted")
        sys.exit(130)
    except KeyboardInterrupt:
        err.print("interrupted")
        sys.exit(130)
    except BrokenPipeError:
        sys.exit(1)
    except DischargelabError as exc:
        if debug:
            raise
        err.print(f"error: {cli_message(exc)}", markup=False)
        sys.exit(2)
    except Exception:  # not a user error: show everything, never hide it
        if debug:
            raise
        traceback.print_exc()
        err.print(BUG_LINE, markup=False)
        sys.exit(1)
    sys.exit(code if isinstance(code, int) else 0)

