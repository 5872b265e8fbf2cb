"""Print pip pins that put every dependency at the lower bound pyproject.toml declares.

    python .ci/min_pins.py [--build] [EXTRA ...]

reads ``[project] dependencies`` plus the named optional-dependency groups (and, with
``--build``, ``[build-system] requires``) and turns each ``name>=X`` into ``name==X``;
``name==X`` stays as it is. A requirement without a lower bound is an error: every
dependency must declare the oldest version the test suite is proven against, and CI
installs exactly these pins (.ci/min-versions.sh), so the bounds cannot drift from
what is tested. Only the standard library is used (it runs before any install).
"""

from __future__ import annotations

import re
import sys
import tomllib
from pathlib import Path

PYPROJECT = Path(__file__).resolve().parent.parent / "pyproject.toml"
# name, optional [extras], specifiers, optional ; marker
REQUIREMENT = re.compile(
    r"^\s*(?P<name>[A-Za-z0-9][A-Za-z0-9._-]*)\s*(?P<extras>\[[^\]]*\])?\s*"
    r"(?P<spec>[^;]*?)\s*(?:;\s*(?P<marker>.+))?$"
)


def pin(requirement: str) -> str:
    """``"numpy>=2.0"`` -> ``"numpy==2.0"`` (extras and environment markers kept)."""
    m = REQUIREMENT.match(requirement)
    if m is None:
        raise SystemExit(f"min_pins: cannot parse requirement {requirement!r}")
    specs = [s.strip() for s in m["spec"].split(",") if s.strip()]
    lower = [s[2:].strip() for s in specs if s.startswith((">=", "=="))]
    if len(lower) != 1:
        raise SystemExit(
            f"min_pins: {requirement!r} needs exactly one '>=' (or '==') lower bound"
        )
    text = f"{m['name']}{m['extras'] or ''}=={lower[0]}"
    if m["marker"]:
        text += f"; {m['marker']}"
    return text


def main(argv: list[str]) -> int:
    data = tomllib.loads(PYPROJECT.read_text(encoding="utf-8"))
    build = "--build" in argv
    extras = [a for a in argv if a != "--build"]
    requirements = list(data["project"].get("dependencies", []))
    groups = data["project"].get("optional-dependencies", {})
    for extra in extras:
        if extra not in groups:
            raise SystemExit(f"min_pins: no optional-dependencies group {extra!r}")
        requirements += groups[extra]
    if build:
        requirements += data["build-system"]["requires"]
    seen: dict[str, str] = {}
    for requirement in requirements:
        line = pin(requirement)
        name = re.split(r"[\[=;]", line, maxsplit=1)[0].lower().replace("_", "-")
        if seen.setdefault(name, line) != line:
            raise SystemExit(f"min_pins: {name} has two lower bounds: {seen[name]!r}, {line!r}")
    print("\n".join(seen.values()))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
