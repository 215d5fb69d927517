"""Print the README table of refused inputs from ``refused_cases.CASES`` (actual messages).

    python tests/stress/refused_table.py > /tmp/refused.md
"""

from __future__ import annotations

import sys
import tempfile
import warnings
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from refused_cases import CASES  # noqa: E402

MAX_MESSAGE = 160


def rows():
    out = []
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        for key, area, what, call, exc, _match in CASES:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                try:
                    call(tmp)
                except Exception as e:  # noqa: BLE001 - we want its class and message
                    got, msg = type(e).__name__, str(e)
                else:
                    got, msg = "(not refused!)", ""
            msg = msg.replace(str(tmp), "<dir>").replace(str(Path(__file__).resolve().parents[1]), "tests")
            msg = " ".join(msg.split())
            if len(msg) > MAX_MESSAGE:
                msg = msg[: MAX_MESSAGE - 3] + "..."
            if got != exc.__name__:
                got = f"{got} (expected {exc.__name__})"
            out.append((area, what, got, msg, key))
    return out


def markdown() -> str:
    lines = ["| area | input | error | message | test id |", "|---|---|---|---|---|"]
    for area, what, got, msg, key in rows():
        esc = msg.replace("|", "\\|")
        lines.append(f"| {area} | {what.replace('|', '/')} | `{got}` | {esc} | `{key}` |")
    return "\n".join(lines)


if __name__ == "__main__":
    print(markdown())
