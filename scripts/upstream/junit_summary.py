"""Print one line per test case of JUnit XML files (pytest's, vitest's), then the totals.

Usage: python3 scripts/upstream/junit_summary.py LABEL FILE.xml [FILE.xml ...]
Each line: LABEL | result (passed, FAILED, skipped) | class::name | first line of the reason.
The closing line is "LABEL: N passed, N failed, N skipped".
"""

from __future__ import annotations

import sys
import xml.etree.ElementTree as ET


def cases(path: str) -> list[tuple[str, str, str]]:
    """(result, name, reason) for each <testcase> in ``path``."""
    rows = []
    for case in ET.parse(path).getroot().iter("testcase"):
        name = f"{case.get('classname', '')}::{case.get('name', '')}"
        result, reason = "passed", ""
        for child in case:
            if child.tag in ("failure", "error"):
                result = "FAILED"
                reason = (child.get("message") or child.text or "").strip()
            elif child.tag == "skipped":
                result = "skipped"
                reason = (child.get("message") or "").strip()
        rows.append((result, name, reason.splitlines()[0][:160] if reason else ""))
    return rows


def main(argv: list[str]) -> int:
    """Print the lines and the totals; always 0 (the runners judge by their own exit code)."""
    label, paths = argv[0], argv[1:]
    counts = {"passed": 0, "FAILED": 0, "skipped": 0}
    for path in paths:
        for result, name, reason in cases(path):
            counts[result] += 1
            print(f"{label} | {result} | {name}" + (f" | {reason}" if reason else ""))
    print(f"{label}: {counts['passed']} passed, {counts['FAILED']} failed, "
          f"{counts['skipped']} skipped")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
