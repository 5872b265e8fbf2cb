"""Sphinx extension: the guides' commands run at build time on the example set.

A block written as

    ```{example-commands}
    dischargelab fit bench/Q30_S001_1C.csv --columns ... -o cell.json
    dischargelab predict cell.json --c-rate 4 --cutoff 2.5
    ```

runs each command, in order, in a folder made for its page by ``dischargelab examples`` (the
files every user can copy), and shows the commands with what they printed. A command that
fails (exit status not 0) fails the build, so a guide cannot drift from the program. Commands
of one page share its folder: a later block can use what an earlier one wrote.

Offline and bounded: only ``dischargelab`` commands (run as ``python -m dischargelab`` with
this checkout's ``src`` first on the path), no shell, each within ``TIMEOUT_S``; the logbook
defaults to a file in the page's folder. ``-D guide_commands_run=0`` shows the commands
without running them (a quick build).
"""

from __future__ import annotations

import os
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

from docutils import nodes
from docutils.parsers.rst import Directive
from sphinx.util import logging

LOG = logging.getLogger(__name__)

#: Longest a single command may run [s].
TIMEOUT_S = 600
#: Lines of a command's output shown on the page (the rest is summarised in one line).
SHOWN_LINES = 40
#: The width commands lay their tables out for.
COLUMNS = 110


def _commands(lines: list[str]) -> list[str]:
    """The block's commands: continuation lines joined, blank and comment lines dropped."""
    commands, current = [], ""
    for line in lines:
        stripped = line.rstrip()
        if stripped.endswith("\\"):
            current += stripped[:-1] + " "
            continue
        current += stripped
        if current.strip() and not current.strip().startswith("#"):
            commands.append(current.strip())
        current = ""
    if current.strip():
        commands.append(current.strip())
    return commands


def _folder(app, docname: str) -> Path:
    """The page's folder holding a fresh copy of the example set (made on first use)."""
    made = app.env.temp_data.setdefault("guide_command_folders", {})
    if docname in made:
        return made[docname]
    folder = Path(app.outdir).parent / "guide-commands" / docname.replace("/", "-")
    shutil.rmtree(folder, ignore_errors=True)
    folder.mkdir(parents=True)
    _run(app, ["dischargelab", "examples", "."], folder)
    made[docname] = folder
    return folder


def _environment(app, folder: Path) -> dict[str, str]:
    env = dict(os.environ)
    src = str(Path(app.confdir).parent / "src")
    env["PYTHONPATH"] = os.pathsep.join([src] + [p for p in [env.get("PYTHONPATH")] if p])
    env.update({"COLUMNS": str(COLUMNS), "NO_COLOR": "1", "TERM": "dumb", "MPLBACKEND": "Agg",
                "DISCHARGELAB_DB": str(folder / "logbook.db")})
    env.pop("FORCE_COLOR", None)
    return env


def _run(app, argv: list[str], folder: Path) -> subprocess.CompletedProcess:
    if not argv or argv[0] != "dischargelab":
        raise ValueError(f"only dischargelab commands run in the guides, got {argv[:1]}")
    return subprocess.run([sys.executable, "-m", "dischargelab", *argv[1:]], cwd=folder,
                          env=_environment(app, folder), capture_output=True, text=True,
                          timeout=TIMEOUT_S, check=False)


def _shown(text: str) -> str:
    lines = text.rstrip().splitlines()
    if len(lines) <= SHOWN_LINES:
        return "\n".join(lines)
    return "\n".join(lines[:SHOWN_LINES] + [f"[... {len(lines) - SHOWN_LINES} more lines]"])


class ExampleCommands(Directive):
    """Run the block's commands in the page's example folder; show them and their output."""

    has_content = True

    def run(self):
        app = self.state.document.settings.env.app
        docname = self.state.document.settings.env.docname
        commands = _commands(list(self.content))
        if not app.config.guide_commands_run:
            text = "\n".join(commands)
            return [nodes.literal_block(text, text, language="bash")]
        folder = _folder(app, docname)
        shown = []
        for command in commands:
            argv = shlex.split(command, comments=True)
            try:
                done = _run(app, argv, folder)
            except (ValueError, subprocess.TimeoutExpired) as exc:
                return [self.state.document.reporter.error(
                    f"{docname}: `{command}`: {exc}", line=self.lineno)]
            output = _shown((done.stdout or "") + (done.stderr or ""))
            if done.returncode != 0:
                return [self.state.document.reporter.error(
                    f"{docname}: `{command}` failed (exit status {done.returncode}): "
                    f"{output[-2000:]}", line=self.lineno)]
            shown.append(f"$ {command}" + (f"\n{output}" if output else ""))
        text = "\n\n".join(shown)
        return [nodes.literal_block(text, text, language="text")]


def setup(app):
    app.add_config_value("guide_commands_run", True, "env", [bool, int])
    app.add_directive("example-commands", ExampleCommands)
    return {"parallel_read_safe": False, "parallel_write_safe": True}
