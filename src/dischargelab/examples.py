"""The example set shipped with the package: a few real files to try every command on.

``dischargelab examples DIR`` (or :func:`copy_examples`) copies them into a folder of the
user's; :func:`example_files` gives where they are inside the installed package. The set:

======================  ====================================================================
``bench/``              three constant-current discharges of one Samsung INR18650-30Q cell
                        (C/10, 1C, 4C = 0.3, 3, 12 A, full charge to 2.5 V; no header:
                        time, current (discharge negative), voltage, power, temperature ...)
``flight/``             a PX4 ULog flight of a 6S multirotor with the battery's voltage and
                        current (27-74 A in flight)
``tester/``             an Arbin tester's CSV export: an LFP 18650 cell, two full discharges
``ageing/``             one Samsung 30Q cell cycled at 3 A: the discharges of cycles 1, 330, 664
``mission/``            a fixed-wing survey mission (TOML) for a 4S2P pack of the bench cell
======================  ====================================================================

Every file is a measurement made by others and shared under a licence that allows
redistribution (CC BY-SA 4.0, MIT, Apache-2.0): the copied folder holds each licence and
a README naming the source of each file (the package's NOTICE says the same).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path

from .atomic import OutputError, check_outputs, write_bytes

__all__ = ["EXAMPLE_COLUMNS", "ExampleSet", "copy_examples", "example_files"]

#: The bench files' columns (no header in the files), as ``--columns`` takes them.
EXAMPLE_COLUMNS = "time_s=0,current_A=1,voltage_V=2,temperature_C=4"

#: Each file of the set: its place in the copied folder -> its place under the package's
#: ``data`` folder. The bench discharges, the flight log and the mission are the files the
#: demo and ``endurance`` use already (no second copy in the package).
_FILES = {
    "bench/Q30_S001_C10.csv": "samsung30q/Q30_S001_C10.csv",
    "bench/Q30_S001_1C.csv": "samsung30q/Q30_S001_1C.csv",
    "bench/Q30_S001_4C.csv": "samsung30q/Q30_S001_4C.csv",
    "bench/LICENSE": "samsung30q/LICENSE",
    "flight/esc_status_log.ulg": "flightlogs/esc_status_log.ulg",
    "flight/LICENSE": "flightlogs/LICENSE-px4-ulog-rs",
    "tester/arbin_example.csv": "examples/tester/arbin_example.csv",
    "tester/LICENSE": "examples/tester/LICENSE-battery-data-toolkit",
    "ageing/DischargeCycle001.txt": "examples/ageing/DischargeCycle001.txt",
    "ageing/DischargeCycle330.txt": "examples/ageing/DischargeCycle330.txt",
    "ageing/DischargeCycle664.txt": "examples/ageing/DischargeCycle664.txt",
    "ageing/LICENSE": "examples/ageing/LICENSE",
    "mission/survey.toml": "examples/mission/survey.toml",
    "README.txt": "examples/README.txt",
}

#: What to try first in a copied folder (the user guide's first commands).
NEXT_COMMANDS = (
    f"dischargelab fit bench/Q30_S001_C10.csv bench/Q30_S001_4C.csv --columns "
    f"{EXAMPLE_COLUMNS} -o cell.json",
    f"dischargelab validate cell.json bench/Q30_S001_1C.csv --columns {EXAMPLE_COLUMNS} "
    "--cutoff 2.5",
    "dischargelab endurance cell.json mission/survey.toml --cells 4 --parallel 2",
    "dischargelab flight flight/esc_status_log.ulg",
    "dischargelab steps tester/arbin_example.csv",
    "dischargelab logbook add ageing --pack cell-C --db packs.db",
)


def _data() -> Path:
    return Path(str(resources.files("dischargelab") / "data"))


def example_files() -> dict[str, Path]:
    """The example set inside the installed package.

    Returns
    -------
    dict
        ``{name in the copied folder (e.g. "bench/Q30_S001_1C.csv"): path of the file in the
        package}``; read the files from there, or copy them with :func:`copy_examples`.
    """
    data = _data()
    return {name: data / source for name, source in _FILES.items()}


@dataclass(frozen=True)
class ExampleSet:
    """The example set copied into a folder (:func:`copy_examples`).

    Attributes
    ----------
    folder : Path
        Where the set is.
    files : dict
        ``{name (e.g. "bench/Q30_S001_1C.csv"): path in folder}``, every file of the set.
    written : list of Path
        The files this call wrote (all of them, unless some were there and identical).
    next_commands : tuple of str
        Commands to try in ``folder``.
    """

    folder: Path
    files: dict[str, Path]
    written: list[Path] = field(default_factory=list)
    next_commands: tuple[str, ...] = NEXT_COMMANDS

    def __getitem__(self, name: str) -> Path:
        return self.files[name]

    def to_dict(self) -> dict:
        """JSON-ready: the folder, every file, the files written, the next commands."""
        return {"folder": str(self.folder),
                "files": {name: str(path) for name, path in self.files.items()},
                "written": [str(p) for p in self.written],
                "next_commands": list(self.next_commands)}


def copy_examples(folder, *, force: bool = False) -> ExampleSet:
    """Copy the example set into ``folder`` (created when missing).

    Parameters
    ----------
    folder : path
        Where to put the files; the set's sub-folders (``bench/``, ``flight/`` ...) are made
        inside it.
    force : bool
        Replace files of the set that are already there with other contents. A file that
        is there with the same contents is left as it is, so copying twice is harmless.

    Returns
    -------
    ExampleSet
        The paths of the copied files, those written, and the commands to try next.

    Raises
    ------
    OutputExistsError
        A file of the set is there with other contents and ``force`` is false (nothing is
        written then).
    OutputError
        ``folder`` or a place of the set in it is a file where a folder is needed, or the
        other way round.
    """

    folder = Path(folder)
    if folder.exists() and not folder.is_dir():
        raise OutputError(f"{folder} is a file; give a folder for the examples")
    sources = example_files()
    targets = {name: folder / name for name in sources}
    changed = []
    for name, target in targets.items():
        for parent in target.relative_to(folder).parents:
            if str(parent) != "." and (folder / parent).is_file():
                raise OutputError(f"{folder / parent} is a file; the examples need a folder "
                                  "there: copy them into another folder")
        if target.is_file() and target.read_bytes() == sources[name].read_bytes():
            continue
        changed.append(name)
    # the policy for every file before any is written: all of the set or nothing
    check_outputs([targets[name] for name in changed], inputs=sources.values(), force=force)
    written = []
    for name in changed:
        targets[name].parent.mkdir(parents=True, exist_ok=True)
        written.append(write_bytes(targets[name], sources[name].read_bytes()))
    return ExampleSet(folder=folder, files=targets, written=written)
