"""Run the command line in-process for tests."""

import pytest

from dischargelab.cli import main


def run(capsys, *args):
    """Run the CLI in-process; return (exit code, stdout, stderr)."""
    with pytest.raises(SystemExit) as exc:
        main([str(a) for a in args])
    captured = capsys.readouterr()
    return exc.value.code, captured.out, captured.err


def command(*args, cwd=None, env=None, check=True, timeout=900):
    """``python -m dischargelab ARGS`` in a fresh process, as a user runs it (a wide terminal,
    this checkout's sources, ``env`` added); fails on a non-zero exit when ``check``."""
    import os
    import subprocess
    import sys
    from pathlib import Path

    import dischargelab

    done = subprocess.run([sys.executable, "-m", "dischargelab", *map(str, args)],
                          capture_output=True, text=True, cwd=cwd, timeout=timeout,
                          env={**os.environ, "COLUMNS": "200",
                               "PYTHONPATH": str(Path(dischargelab.__file__).parents[1]),
                               **(env or {})})
    if check:
        assert done.returncode == 0, done.stderr[-3000:] + done.stdout[-3000:]
    return done


def stored_rows(db) -> dict:
    """Every row of every table of a SQLite logbook, in a fixed order."""
    import sqlite3

    with sqlite3.connect(db) as conn:
        tables = [r[0] for r in conn.execute(
            "SELECT name FROM sqlite_master WHERE type='table' ORDER BY name")]
        return {t: sorted(map(repr, conn.execute(f'SELECT * FROM "{t}"'))) for t in tables}
