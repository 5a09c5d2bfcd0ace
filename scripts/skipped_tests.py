#!/usr/bin/env python3
"""Prints how many tests ctest skipped and why, from its JUnit report (ctest --output-junit).

Usage: skipped_tests.py REPORT.xml

The reason of a skip is the test's own line: a Google Test's message after "Skipped" (e.g. the
shared data it did not find), or a script's line starting with "skip:" (exit code 77). Skips with
the same reason are counted together, with the first few tests named.
"""
import collections
import sys
import xml.etree.ElementTree as ElementTree


def skip_reason(testcase):
    lines = (testcase.findtext("system-out") or "").splitlines()
    for i, line in enumerate(lines):
        if line.endswith(": Skipped") and i + 1 < len(lines) and lines[i + 1].strip():
            return lines[i + 1].strip()
        if line.startswith("skip:"):
            return line[len("skip:"):].strip()
    skipped = testcase.find("skipped")
    return skipped.get("message", "no reason given") if skipped is not None else "no reason given"


def main():
    if len(sys.argv) != 2:
        sys.exit(__doc__)
    cases = ElementTree.parse(sys.argv[1]).getroot().iter("testcase")
    total = 0
    reasons = collections.OrderedDict()
    for case in cases:
        total += 1
        if case.get("status") == "notrun" and case.find("skipped") is not None:
            reasons.setdefault(skip_reason(case), []).append(case.get("name"))
    skipped = sum(len(names) for names in reasons.values())
    print(f"{skipped} of {total} tests skipped" + (":" if skipped else ""))
    for reason, names in reasons.items():
        shown = ", ".join(names[:3]) + (f" and {len(names) - 3} more" if len(names) > 3 else "")
        print(f"  {len(names)} x {reason}\n      ({shown})")


if __name__ == "__main__":
    main()
