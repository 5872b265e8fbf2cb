"""examples: copy the example set (real files to try every command on) into a folder."""

from __future__ import annotations

import click

from .common import force_option, json_option, out, print_json


@click.command("examples")
@click.argument("folder", type=click.Path(file_okay=False))
@force_option
@json_option
def examples_cmd(folder, force, as_json):
    """Copy the example set into FOLDER: bench discharges, a flight log, a tester file,
    an ageing cell and a mission.

    Real measurements shipped with dischargelab (each with its licence and source in
    FOLDER/README.txt); the user guide's commands run on them. Files already there with
    the same contents are kept; other files of the same name are not replaced without
    --force.

    \b
    Examples:
      dischargelab examples try-me
      cd try-me && dischargelab steps tester/arbin_example.csv
    """
    from ..examples import copy_examples

    result = copy_examples(folder, force=force)
    if as_json:
        print_json(result.to_dict())
        return
    kept = len(result.files) - len(result.written)
    out.print(f"examples in {result.folder}: wrote {len(result.written)} files"
              + (f", {kept} already there" if kept else ""), markup=False)
    for path in result.written:
        out.print(f"  {path}", markup=False)
    out.print(f"\nnext, in {result.folder}:", markup=False)
    for command in result.next_commands:
        out.print(f"  {command}", markup=False)


COMMANDS = [examples_cmd]
