"""Machine description printed under every benchmark table, and the plain-text table."""

import os
import platform
from datetime import UTC, datetime


def machine_line() -> str:
    """One line: date, CPU model, cores, Python and numpy/scipy versions."""
    import numpy
    import scipy

    cpu = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as fh:
            for line in fh:
                if line.startswith("model name"):
                    cpu = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    now = datetime.now(UTC).strftime("%Y-%m-%d %H:%M UTC")
    return (f"{now}; {cpu}; {os.cpu_count()} cores; Python {platform.python_version()}; "
            f"numpy {numpy.__version__}; scipy {scipy.__version__}")


def table(title: str, head: list[str], rows: list[list]) -> None:
    """Print a titled table with left-aligned columns."""
    print(f"\n{title}")
    widths = [max(len(str(x)) for x in [h] + [r[k] for r in rows]) for k, h in enumerate(head)]
    print("  ".join(str(h).ljust(w) for h, w in zip(head, widths)))
    print("  ".join("-" * w for w in widths))
    for r in rows:
        print("  ".join(str(x).ljust(w) for x, w in zip(r, widths)))
